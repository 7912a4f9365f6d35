"""A video stream's frames with PyAV: its timestamps from one pass over the packets (no
decoding), and each frame decoded on demand.

``probe`` demuxes the stream once and returns the presentation times (``pts``, sorted: B-frames
come out of order) and the keyframes. AVI stores decoding times only (FFmpeg guesses its pts):
its frame times are the packets' sorted dts. AVI frames, and those of a stream without
timestamps (whose times are ``position / average_rate``), are found by their position in the
order the decoder gives them, so a step back decodes from the start.

``VideoFrame(path, stream, pts, keyframe, resume, timed, grey)`` is a frame's source for ``FrameRecord.image``:
a small picklable object whose call returns the frame as HxWx3 uint8 RGB. It asks this process's
decoder of the stream (one per video and stream, opened on first use, again after a fork or once
the file changed), which seeks to the keyframe before the frame and decodes forward, or goes on
decoding without a seek when the frame lies ahead, at most two keyframe intervals on: reading a
video in order decodes each frame once, with no seek.
"""

from __future__ import annotations

import ctypes
import os
import threading
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from sal_adapters.common.errors import DatasetError

__all__ = ["MAX_OPEN_DECODERS", "StreamInfo", "VideoFrame", "import_av", "probe"]

#: Decoders a process keeps open (least recently used closed first).
MAX_OPEN_DECODERS = 8


def import_av() -> Any:
    """The ``av`` module (PyAV); ``DatasetError`` saying how to install it when it is missing."""
    try:
        import av
        import av.logging
    except ImportError as exc:
        raise DatasetError(f"the video dataset kind needs PyAV: pip install 'pytest-sal[video]' ({exc})") from None
    level = av.logging.get_level()
    if level is not None and level > av.logging.PANIC:  # PyAV < 13 prints FFmpeg's log; our errors say what went wrong
        av.logging.set_level(av.logging.PANIC)
    return av


@dataclass(frozen=True)
class StreamInfo:
    """A video stream as ``probe`` found it.

    Attributes:
        index: the stream's position among the file's streams (all kinds).
        width, height: frame size (px).
        pts: what identifies each frame to a decoder: its presentation time in ``time_base``
            units (increasing) when ``timed``, else its position ``0, 1, ...``.
        times: the frames' times in ``time_base`` units, increasing, or ``None`` when the
            stream has none (then ``position / average_rate``).
        keyframes: for each frame, the ``pts`` of the last keyframe at or before it (where a
            decoder seeks to).
        resume: for each frame, the keyframe before that one: a decoder that has given a frame
            from there on goes on decoding forward rather than seek (at most two keyframe
            intervals, and none at all when a video is read in order).
        time_base: the unit of ``pts`` (s). average_rate: frames per second, or ``None``.
        codec, pix_fmt, bit_rate (bit/s, 0 = unknown), color_range (FFmpeg's number),
        container: what the stream and file are.
    """

    index: int
    width: int
    height: int
    pts: list[int]
    times: list[int] | None
    keyframes: list[int]
    resume: list[int]
    timed: bool
    time_base: Fraction
    average_rate: Fraction | None
    codec: str
    pix_fmt: str
    bit_rate: int
    color_range: int
    container: str

    def times_ns(self) -> list[int]:
        """Frame times (ns) from the first frame, exact (``Fraction`` arithmetic)."""
        if self.times is None:
            rate = self.average_rate or Fraction(30)
            return [round(Fraction(10**9) * position / rate) for position in range(len(self.pts))]
        return [round((t - self.times[0]) * self.time_base * 10**9) for t in self.times]


class _Packet(NamedTuple):
    pts: int | None
    dts: int | None
    keyframe: bool


def probe(path: Path, stream: int) -> StreamInfo:
    """The ``stream``-th video stream of ``path``, its packets read once (nothing decoded).

    Raises:
        DatasetError: naming ``path``: not a video PyAV can open, no such video stream (saying
            how many there are), no frames, or fewer packets than the file's index lists (cut off).
    """
    av = import_av()
    try:
        container = av.open(str(path))
    except (av.FFmpegError, UnicodeDecodeError) as exc:
        raise DatasetError(f"not a video file FFmpeg can read ({_reason(exc)}); a cut-off MP4 loses its index at the end", path) from None
    with container:
        videos = container.streams.video
        if not videos:
            kinds = ", ".join(s.type for s in container.streams) or "none"
            raise DatasetError(f"no video stream in the file (streams: {kinds})", path)
        if isinstance(stream, bool) or not isinstance(stream, int) or not 0 <= stream < len(videos):
            raise DatasetError(
                f"option stream={stream!r}: the file has {len(videos)} video stream{'s' if len(videos) > 1 else ''} "
                f"(stream=0..{len(videos) - 1})",
                path,
            )
        video = videos[stream]
        context = video.codec_context
        info = StreamInfo(
            index=video.index,
            width=int(context.width or 0),
            height=int(context.height or 0),
            pts=[],
            times=None,
            keyframes=[],
            resume=[],
            timed=False,
            time_base=Fraction(video.time_base or Fraction(1, 90000)),
            average_rate=None if not video.average_rate else Fraction(video.average_rate),
            codec=str(context.name),
            pix_fmt=str(context.pix_fmt or ""),
            bit_rate=int(video.bit_rate or context.bit_rate or 0),
            color_range=int(context.color_range or 0),
            container=str(container.format.name),
        )
        packets = _packets(container, video, path, check_count=info.container != "avi")  # AVI counts empty chunks
    return _ordered(info, packets, path)


def _packets(container: Any, video: Any, path: Path, check_count: bool) -> list[_Packet]:
    """The stream's packets in decoding order (empty ones skipped); with ``check_count``,
    ``DatasetError`` when there are fewer than the file's index lists (cut off)."""
    av = import_av()
    packets: list[_Packet] = []
    try:
        for packet in container.demux(video):
            if packet.size:  # not the end-of-stream marker
                packets.append(_Packet(packet.pts, packet.dts, bool(packet.is_keyframe)))
    except av.FFmpegError as exc:
        raise DatasetError(f"damaged video: reading stops after {len(packets)} frames ({_reason(exc)})", path) from None
    if check_count and video.frames and len(packets) < video.frames:
        raise DatasetError(f"cut off: the file's index lists {video.frames} frames, but only {len(packets)} are in it", path)
    if not packets:
        raise DatasetError("the video stream has no frames", path)
    return packets


def _ordered(info: StreamInfo, packets: list[_Packet], path: Path) -> StreamInfo:
    """``info`` with its frames in presentation order, their times and seek points.

    AVI stores decoding times only (FFmpeg guesses the pts): its times are the sorted dts, and
    its frames, like those of a stream without timestamps, are found by their position.
    """
    if info.width < 1 or info.height < 1:
        raise DatasetError(f"the video stream has no frame size ({info.width}x{info.height} px)", path)
    count = len(packets)
    if info.container == "avi" or any(p.pts is None for p in packets):
        stamps = None if any(p.dts is None for p in packets) else sorted(int(p.dts or 0) for p in packets)
        _check_increasing(stamps or [], info, path)
        return _replace(info, pts=list(range(count)), times=stamps, keyframes=[0] * count, resume=[0] * count)
    pts = sorted(int(p.pts or 0) for p in packets)
    _check_increasing(pts, info, path)
    keys = sorted(int(p.pts or 0) for p in packets if p.keyframe) or [pts[0]]
    keyframes, resume, k = [], [], 0
    for t in pts:
        while k + 1 < len(keys) and keys[k + 1] <= t:
            k += 1
        keyframes.append(min(keys[k], t))
        resume.append(min(keys[max(k - 1, 0)], t))
    return _replace(info, pts=pts, times=pts, keyframes=keyframes, resume=resume, timed=True)


def _check_increasing(stamps: list[int], info: StreamInfo, path: Path) -> None:
    repeated = next((a for a, b in zip(stamps, stamps[1:]) if a == b), None)
    if repeated is not None:
        raise DatasetError(f"two frames have the same timestamp ({repeated} x {info.time_base} s)", path)


def _replace(info: StreamInfo, **changes: Any) -> StreamInfo:
    return StreamInfo(**{**info.__dict__, **changes})


def _reason(exc: BaseException) -> str:
    """FFmpeg's reason for ``exc``, without the path it repeats."""
    return str(getattr(exc, "strerror", None) or exc)


@dataclass(frozen=True)
class VideoFrame:
    """One frame of a video as a ``FrameRecord`` source: calling it decodes the frame (HxWx3
    uint8 RGB; a ``grey`` frame's luma in all three channels). ``pts``, ``keyframe`` and
    ``resume`` are as in ``StreamInfo``; ``stream`` is the position among the video streams."""

    path: str
    stream: int
    pts: int
    keyframe: int
    resume: int
    timed: bool = True
    grey: bool = False

    def __call__(self) -> np.ndarray:
        decoder = _DECODERS.get(self.path, self.stream)
        with decoder.lock:
            return decoder.frame(self)


class _Decoder:
    """One open video stream: the container, the frames it is decoding and the last one's key."""

    def __init__(self, path: str, stream: int, stamp: tuple[int, int]):
        av = import_av()
        self.path, self.stamp, self.lock = path, stamp, threading.Lock()
        try:
            self.container = av.open(path)
            self.stream = self.container.streams.video[stream]
            self.stream.thread_type = "AUTO"
        except (av.FFmpegError, IndexError) as exc:
            raise DatasetError(f"cannot open the video stream {stream} again ({_reason(exc)})", path) from None
        self.frames: Iterator[tuple[int, Any]] | None = None
        self.last: int | None = None

    def frame(self, want: VideoFrame) -> np.ndarray:
        """Decode ``want``: forward from the last frame given when ``want`` lies ahead of it and
        it is at or after ``want.resume``, else after a seek to ``want``'s keyframe."""
        av = import_av()
        if self.frames is None or self.last is None or not want.resume <= self.last < want.pts:
            self._seek(want)
        assert self.frames is not None
        try:
            for key, frame in self.frames:
                self.last = key
                if key == want.pts:
                    return _rgb(frame, want.grey, self.stream.codec_context.color_range)
                if key > want.pts:
                    break
        except av.FFmpegError as exc:
            self.frames = None
            raise DatasetError(f"cannot decode the frame at pts {want.pts} ({_reason(exc)})", self.path) from None
        self.frames = None
        raise DatasetError(f"the video has no frame at pts {want.pts} (changed since it was opened?)", self.path)

    def _seek(self, want: VideoFrame) -> None:
        if want.timed:
            self.container.seek(want.keyframe, stream=self.stream, backward=True, any_frame=False)
        else:
            self.container.seek(0)
        self.frames = self._decode(want.timed)
        self.last = None

    def _decode(self, timed: bool) -> Iterator[tuple[int, Any]]:
        """``(key, frame)`` in presentation order: key = pts, or the decoding position."""
        position = 0
        for packet in self.container.demux(self.stream):
            if not packet.size:  # the end-of-stream marker (flushed below) and AVI's empty chunks
                continue
            for frame in packet.decode():
                yield (frame.pts if timed and frame.pts is not None else position), frame
                position += 1
        for frame in self.stream.codec_context.decode(None):
            yield (frame.pts if timed and frame.pts is not None else position), frame
            position += 1


def _rgb(frame: Any, grey: bool, stream_range: int | None) -> np.ndarray:
    """A decoded frame as HxWx3 uint8 RGB, converted with its colour range (PyAV < 13 leaves
    the frame's unspecified: the stream's, else MPEG's limited range); a grey frame's luma
    exactly (no range scaling when the stream is full range) in all channels."""
    from av.video.reformatter import ColorRange

    source_range = int(getattr(frame, "color_range", 0) or stream_range or ColorRange.MPEG)
    if grey:
        luma = frame.reformat(format="gray", src_color_range=source_range, dst_color_range=ColorRange.JPEG).to_ndarray()
        return np.repeat(luma[:, :, None], 3, axis=2)
    return np.ascontiguousarray(frame.reformat(format="rgb24", src_color_range=source_range).to_ndarray())


class _DecoderCache:
    """This process's open decoders by video and stream (emptied in a forked child)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.open: OrderedDict[tuple[str, int], _Decoder] = OrderedDict()
        os.register_at_fork(after_in_child=self._forked)

    def _forked(self) -> None:
        """In a forked child: new decoders; the inherited ones are never freed (freeing waits
        for their FFmpeg threads, which exist in the parent only, forever)."""
        for decoder in self.open.values():
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(decoder))
        self.lock = threading.Lock()
        self.open = OrderedDict()

    def get(self, path: str, stream: int) -> _Decoder:
        """The decoder of ``path``'s ``stream``, reopened when the file changed."""
        try:
            st = os.stat(path)
        except OSError as exc:
            raise DatasetError(f"video file not readable ({exc.strerror})", path) from None
        stamp, key = (st.st_size, st.st_mtime_ns), (path, stream)
        with self.lock:
            decoder = self.open.get(key)
            if decoder is None or decoder.stamp != stamp:
                decoder = self.open[key] = _Decoder(path, stream, stamp)
            self.open.move_to_end(key)
            while len(self.open) > MAX_OPEN_DECODERS:
                self.open.popitem(last=False)  # closed when its last frame call returns
            return decoder


_DECODERS = _DecoderCache()
