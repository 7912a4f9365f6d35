"""A video file (``.mp4``, ``.mkv``, ``.avi``, ``.mov``) as a monocular sequence, read and
written with PyAV (the ``video`` extra).

Frame times come from the container's timestamps (``pts x time_base``, from the first frame, plus
the sidecar's ``time_offset_s``); frames are decoded on demand (``sal_adapters.video_frames``).
The camera comes from the ``intrinsics`` option or the sidecar YAML beside the video
(``clip.yaml``, format in ``sal_adapters.video_sidecar``), the ground truth from a TUM file.

Writing encodes the frames with their times as pts, so dropped frames leave gaps, and a keyframe
every second (random access decodes at most a second of frames):

* a sequence read from a video keeps its codec, pix_fmt, bit rate and time base (its compression,
  not its exact pixels) where this PyAV build can encode them, else it falls back (warned) to:
* near-lossless libx264 for any other sequence: ``crf 0`` (x264's lossless mode, preset
  ultrafast) in ``gray`` (full range) for grey cameras, which decodes to exactly the original
  pixels (KITTI 07: max error 0), and in ``yuv444p`` for colour, which loses only the RGB -> YUV
  rounding (TUM fr3 images: max 2, mean 0.38 grey levels); time base 1/1000000 s, so times
  survive within 0.5 us (``.mkv`` stores ms: 0.5 ms);
* ``.avi`` stores a constant rate: its time base is one frame period and times are rounded to
  it; use another container to keep them.

Beside the video go the sidecar (camera, ``fps``, ``grayscale``, ``time_offset_s``: the first
frame's time) and, with ground truth, ``<stem>.groundtruth.txt`` (TUM, on the frames' clock).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from fractions import Fraction
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters.common.atomic import writing
from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.datasets import DatasetKind
from sal_adapters.layout_io import checked_image, fps_from_timestamps
from sal_adapters.sequence import Frame, FrameRecord, Sequence
from sal_adapters.trajectory import Trajectory
from sal_adapters.video_frames import StreamInfo, VideoFrame, import_av, probe
from sal_adapters.video_sidecar import Sidecar, read_sidecar, resolve_camera, write_sidecar

__all__ = ["FINE_TIME_BASE", "VIDEO", "VIDEO_SUFFIXES", "VideoDataset"]

VIDEO_SUFFIXES = (".mp4", ".mkv", ".avi", ".mov")
#: Time base (s) of the videos written from non-video sources.
FINE_TIME_BASE = Fraction(1, 1_000_000)
#: FFmpeg's colour ranges: limited (16..235) and full (0..255).
_MPEG_RANGE, _JPEG_RANGE = 1, 2
#: The ground-truth file written beside ``<stem>.mp4``.
_GROUNDTRUTH_SUFFIX = ".groundtruth.txt"


@dataclass(frozen=True)
class _Plan:
    """How ``write_file`` encodes: codec, pixel format, time base (s), bit rate (bit/s, 0 = the
    encoder's quality setting), FFmpeg colour range and encoder options."""

    codec: str
    pix_fmt: str
    time_base: Fraction
    bit_rate: int = 0
    color_range: int = _MPEG_RANGE
    options: dict[str, str] = field(default_factory=dict)


class VideoDataset(DatasetKind):
    """A video file as a monocular sequence."""

    name = "video"
    description = "video file (.mp4 .mkv .avi .mov, PyAV) + sidecar <stem>.yaml (fx fy cx cy, time_offset_s, groundtruth)"
    opens_files = True
    file_suffixes = VIDEO_SUFFIXES

    def open(
        self,
        path: Path | None,
        *,
        intrinsics: tuple[float, float, float, float] | str | None = None,
        distortion: tuple[float, ...] | str | None = None,
        camera_yaml: str | Path | None = None,
        groundtruth: str | Path | None = None,
        stream: int = 0,
    ) -> Sequence:
        """Open a video; nothing is decoded until a frame's image is read.

        Args:
            path: the video file.
            intrinsics: ``(fx, fy, cx, cy)`` (px), replacing the sidecar's; no distortion unless
                ``distortion`` is given.
            distortion: OpenCV coefficients ``(k1, k2, p1, p2[, k3 ...])``.
            camera_yaml: the sidecar (or an ORB-SLAM3 settings file); default ``<stem>.yaml``
                beside the video, when it exists.
            groundtruth: a TUM file (camera-to-world poses, times on the frames' clock);
                default the sidecar's ``groundtruth``.
            stream: which video stream (0 = the first).

        Raises:
            DatasetError: naming the file (and key or option) that is wrong.
        """
        video = _video_path(path)
        info = probe(video, stream)
        looked_for, sidecar = _sidecar(video, camera_yaml)
        camera = resolve_camera(video, info.width, info.height, sidecar, looked_for, intrinsics, distortion)
        offset = 0 if sidecar is None else sidecar.time_offset_ns
        grey = info.pix_fmt.startswith("gray") if sidecar is None or sidecar.grayscale is None else sidecar.grayscale
        resolved = str(video.resolve())
        records = []
        for position, (ns, pts, keyframe, resume) in enumerate(zip(info.times_ns(), info.pts, info.keyframes, info.resume)):
            source = VideoFrame(resolved, stream, pts, keyframe, resume, info.timed, grey)
            records.append(FrameRecord(position, (offset + ns) / 10**9, f"{position:06d}", source, timestamp_ns=offset + ns))
        gt_path = _option_file(groundtruth, video, "groundtruth", "ground-truth file")
        if gt_path is None and sidecar is not None:
            gt_path = sidecar.groundtruth
        stat = video.stat()
        return Sequence(
            kind=self.name,
            name=f"video/{video.stem}",
            camera=camera,
            sensor="mono",
            fps=_fps(info, sidecar, records),
            records=records,
            groundtruth=None if gt_path is None else Trajectory.read_tum(gt_path),
            grayscale=grey,
            source=video,
            meta=_meta(info, offset, sidecar),
            content_key=f"video:{resolved}:{stat.st_size}:{stat.st_mtime_ns}:{stream}",
        )

    def details(self, sequence: Sequence) -> list[tuple[str, str]]:
        """The stream's codec, pixel format, bit rate, time base and container; the sidecar read."""
        meta = sequence.meta
        if "codec" not in meta:
            return []
        rate = f", {meta['bit_rate'] / 1e6:.2f} Mbit/s" if meta.get("bit_rate") else ""
        return [
            ("video", f"{meta['codec']} {meta['pix_fmt']}{rate}, time base {meta['time_base']} s, container {meta['format']}"),
            ("sidecar", f"{meta.get('sidecar') or 'none'} (time_offset_s {meta['time_offset_s']} s)"),
        ]

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write ``out_dir/<name>.mp4`` and its sidecars (``write_file``); return the video."""
        path = Path(out_dir) / f"{_safe_stem(sequence.name)}.mp4"
        self.write_file(sequence, path, frames)
        return path

    def write_file(self, sequence: Sequence, path: Path, frames: Iterable[Frame]) -> None:
        """Encode ``frames`` (``sequence``'s, in order) into ``path`` (container from its suffix)
        with ``<stem>.yaml`` and, with ground truth, ``<stem>.groundtruth.txt`` beside it. A
        stereo or RGB-D sequence gives its left images only (warned)."""
        path = Path(path)
        if sequence.sensor != "mono":
            lost = "right images" if sequence.sensor == "stereo" else "depth maps"
            warnings.warn(
                f"{sequence.name}: a video holds one camera; writing the left images only (the {lost} are not written)",
                DatasetWarning,
                stacklevel=4,
            )
        plan = _plan(sequence, path.suffix.lower())
        with writing(path):
            first_ns = _encode(sequence, path, frames, plan)
        gt_name = None
        if sequence.groundtruth is not None:
            gt_name = path.stem + _GROUNDTRUTH_SUFFIX
            sequence.groundtruth.write_tum(path.with_name(gt_name))
        write_sidecar(
            path.with_suffix(".yaml"),
            sequence.camera,
            fps=sequence.fps,
            grayscale=sequence.grayscale,
            time_offset_ns=first_ns,
            groundtruth=gt_name,
            written_from=f"{sequence.name} ({sequence.kind}), encoded as {plan.codec} {plan.pix_fmt} in {path.name}",
        )


# -- opening ---------------------------------------------------------------------------------------
def _video_path(path: Path | None) -> Path:
    if path is None:
        raise DatasetError("the video dataset needs a path (the video file)")
    path = Path(path).expanduser()
    if path.is_dir():
        found = sorted(p.name for p in path.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
        hint = f" (found: {', '.join(found[:5])})" if found else ""
        raise DatasetError(f"is a folder; the video dataset opens a video file{hint}", path)
    if not path.is_file():
        raise DatasetError("video file not found", path)
    return path


def _option_file(option: object, video: Path, name: str, what: str) -> Path | None:
    """The file an option names: as given, else relative to the video's folder."""
    if option is None:
        return None
    if not isinstance(option, str | PathLike):
        raise DatasetError(f"option {name} must be a file path, got {type(option).__name__}", video)
    path = Path(option).expanduser()
    if not path.is_file() and not path.is_absolute() and (video.parent / path).is_file():
        path = video.parent / path
    if not path.is_file():
        raise DatasetError(f"{what} not found (option {name})", path)
    return path


def _sidecar(video: Path, option: str | Path | None) -> tuple[Path, Sidecar | None]:
    """The sidecar looked for, and what it says (``None`` when the default one is absent)."""
    path = _option_file(option, video, "camera_yaml", "sidecar YAML")
    if path is not None:
        return path, read_sidecar(path)
    default = video.with_suffix(".yaml")
    return default, read_sidecar(default) if default.is_file() else None


def _fps(info: StreamInfo, sidecar: Sidecar | None, records: list[FrameRecord]) -> float:
    """The sidecar's rate, else the stream's average rate, else 1 / the median frame step (Hz)."""
    if sidecar is not None and sidecar.fps is not None:
        return sidecar.fps
    if info.average_rate:
        return float(info.average_rate)
    return fps_from_timestamps(np.array([r.timestamp for r in records]), 30.0)


def _meta(info: StreamInfo, offset_ns: int, sidecar: Sidecar | None) -> dict[str, Any]:
    """What ``write_file`` keeps when the sequence is written as a video again, and what
    ``details`` prints."""
    return {
        "codec": info.codec,
        "pix_fmt": info.pix_fmt,
        "bit_rate": info.bit_rate,
        "time_base": str(info.time_base),
        "color_range": info.color_range,
        "format": info.container,
        "stream_index": info.index,
        "time_offset_s": offset_ns / 10**9,
        "sidecar": None if sidecar is None else str(sidecar.path),
    }


# -- writing ---------------------------------------------------------------------------------------
def _safe_stem(name: str) -> str:
    """A file name stem from a sequence name: its last part, ``kitti/07`` -> ``07``."""
    stem = re.sub(r"[^A-Za-z0-9._+-]+", "_", name.replace("\\", "/").rstrip("/").rsplit("/", 1)[-1]).strip("._")
    return stem or "sequence"


def _plan(sequence: Sequence, suffix: str) -> _Plan:
    """The source video's encoding when ``sequence`` came from one and this PyAV build can
    encode it (else warned), otherwise near-lossless libx264; ``.avi`` gets a constant-rate
    time base and no B-frames (it stores no presentation times)."""
    grey, meta = sequence.grayscale, sequence.meta
    options = {"crf": "0", "preset": "ultrafast"}  # decodes 3x faster than veryfast, 20 % larger
    plans = [_Plan("libx264", "gray" if grey else "yuv444p", FINE_TIME_BASE, 0, _JPEG_RANGE if grey else _MPEG_RANGE, options)]
    if sequence.kind == "video" and meta.get("codec") and meta.get("pix_fmt") and meta.get("time_base"):
        kept = _Plan(
            str(meta["codec"]),
            str(meta["pix_fmt"]),
            Fraction(str(meta["time_base"])),
            int(meta.get("bit_rate") or 0),
            int(meta.get("color_range") or _MPEG_RANGE),
        )
        plans.insert(0, kept)
    if suffix == ".avi":
        rate = Fraction(sequence.fps).limit_denominator(1001)
        plans = [replace(plan, time_base=1 / rate, options={**plan.options, "bf": "0"}) for plan in plans]
    if len(plans) > 1:
        problem = _encoder_problem(plans[0], sequence)
        if problem is None:
            return plans[0]
        warnings.warn(
            f"{sequence.name}: cannot encode as the source video ({plans[0].codec} {plans[0].pix_fmt}: {problem}); "
            f"writing near-lossless {plans[1].codec} {plans[1].pix_fmt} instead",
            DatasetWarning,
            stacklevel=5,
        )
    return plans[-1]


def _encoder_problem(plan: _Plan, sequence: Sequence) -> str | None:
    """Why ``plan`` cannot encode ``sequence``'s frames here, or ``None`` when it can."""
    av = import_av()
    try:
        context = av.CodecContext.create(plan.codec, "w")
        context.width, context.height, context.pix_fmt = sequence.camera.width, sequence.camera.height, plan.pix_fmt
        context.time_base = plan.time_base
        context.open()
    except (av.FFmpegError, ValueError) as exc:
        return str(getattr(exc, "strerror", None) or exc)
    return None


def _encode(sequence: Sequence, path: Path, frames: Iterable[Frame], plan: _Plan) -> int:
    """Encode ``frames`` into ``path`` with pts = (time - first time) / time base; return the
    first frame's time (ns). FFmpeg's refusals become ``DatasetError`` (its I/O errors stay
    ``OSError``)."""
    av = import_av()
    try:
        with av.open(str(path), "w") as container:
            return _encode_into(av, container, sequence, frames, plan)
    except av.FFmpegError as exc:
        if isinstance(exc, OSError):
            raise
        raise DatasetError(f"{sequence.name}: FFmpeg cannot encode {plan.codec} {plan.pix_fmt} in {path.suffix} ({exc})") from None


def _encode_into(av: Any, container: Any, sequence: Sequence, frames: Iterable[Frame], plan: _Plan) -> int:
    camera = sequence.camera
    stream = container.add_stream(plan.codec, rate=Fraction(sequence.fps).limit_denominator(1001))
    stream.width, stream.height, stream.pix_fmt = camera.width, camera.height, plan.pix_fmt
    stream.time_base = stream.codec_context.time_base = plan.time_base
    stream.codec_context.color_range = plan.color_range
    stream.codec_context.gop_size = max(1, round(sequence.fps))  # a keyframe a second: cheap random access
    if plan.bit_rate:
        stream.codec_context.bit_rate = plan.bit_rate
    stream.codec_context.options = dict(plan.options)
    first_ns: int | None = None
    last_ns = last_pts = -1
    for frame in frames:
        ns = _time_ns(frame.record)
        if first_ns is not None and ns <= last_ns:
            raise DatasetError(f"{sequence.name}: frame {frame.index} at {ns} ns does not come after {last_ns} ns")
        first_ns = ns if first_ns is None else first_ns
        picture = _picture(av, checked_image(frame, camera, sequence.name), sequence.grayscale, plan)
        picture.pts = last_pts = max(last_pts + 1, round(Fraction(ns - first_ns, 10**9) / plan.time_base))
        picture.time_base = plan.time_base
        container.mux(stream.encode(picture))
        last_ns = ns
    if first_ns is None:
        raise DatasetError(f"{sequence.name}: no frames to write")
    container.mux(stream.encode(None))
    return first_ns


def _time_ns(record: FrameRecord) -> int:
    """The frame's time (ns): the dataset's own, else the decimal its time (s) was read from
    (``repr``), so that times in us, as TUM's, come back as the same floats."""
    if record.timestamp_ns is not None:
        return record.timestamp_ns
    return round(Fraction(repr(float(record.timestamp))) * 10**9)


def _picture(av: Any, image: np.ndarray, grey: bool, plan: _Plan) -> Any:
    """``image`` (HxWx3 RGB) as a frame in ``plan``'s pixel format; a grey one from its first
    channel, taken as full-range luma."""
    if grey:
        picture = av.VideoFrame.from_ndarray(np.ascontiguousarray(image[:, :, 0]), format="gray")
        return picture.reformat(format=plan.pix_fmt, src_color_range=_JPEG_RANGE, dst_color_range=plan.color_range)
    picture = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")
    return picture.reformat(format=plan.pix_fmt, dst_color_range=plan.color_range)


VIDEO = VideoDataset()
