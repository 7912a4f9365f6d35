"""``bandwidth``: the camera stream squeezed through a constant-bit-rate video link.

Every stream ("left", "right") is encoded as one video with libx264 (H.264) or libx265
(H.265) through PyAV, in process, at the sequence's own frame rate, and decoded again; the
output frames are the decoded pictures. Earlier steps of a chain feed the encoder, so it codes
what they produced, and only the frames they kept.

Mathematical formulation
------------------------
The link carries R = ``target_mbps`` x 10^6 bit/s. A frame at presentation time t_i = pts_i / f
(pts_i = dataset index, f = sequence fps in Hz) is coded into b_i bytes by a rate controller
that keeps the hypothetical reference decoder buffer (VBV) of B = ``buffer_mbit`` x 10^6 bit,
filled at R_max = ``max_mbps`` x 10^6 bit/s, from under- and overflowing:

    0 <= F_i = F_{i-1} + R_max (t_i - t_{i-1}) - 8 b_i <= B

With R_max = R (the default) the stream is strict CBR: x264 ``nal-hrd=cbr`` pads with filler
so that sum_i 8 b_i ~= R x T, where T = (pts_last - pts_first + 1) / f s. x264 runs with
variable-frame-rate rate control (``force-cfr=0``), so frames dropped earlier in a chain leave
time gaps whose bits go to the frames that remain. x265 has no VFR rate control: each coded
frame gets about R / f bits whatever the gaps. The measured rate of each stream is kept in
``measured_mbps[stream] = 8 sum_i b_i / T / 10^6`` (Mbit/s). The buffer starts nearly full, so
a short clip may exceed R by up to B / T (8 sum_i b_i <= R T + B); below about 0.05 Mbit/s at
KITTI size even the coarsest quantiser (QP 51) needs more than R, and the measured rate says so.

Coding settings: ``tune=zerolatency`` (no B-frames, no look-ahead: packet k is frame k),
keyframe every ``gop_frames`` frames (default round(2 f), 2 s), yuv420p (odd widths or heights
are padded by one replicated column/row and cropped after decoding), ``thread_count = 1``
(identical bytes for identical input). The bit stream stays in memory; ``result`` decodes
sequentially with a cursor, restarting at the nearest keyframe when asked for an earlier frame
or one beyond the next keyframe, and keeps only the last decoded picture.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterable
from dataclasses import dataclass, field
from fractions import Fraction
from threading import Lock
from typing import Any

import cv2
import numpy as np

from sal_modules.base import SequencePerturbation
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError
from sal_modules.params import Param

__all__ = ["Bandwidth"]

#: x264 / x265 speed presets, fastest first.
PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
#: codec parameter -> (PyAV encoder, PyAV decoder).
CODECS = {"h264": ("libx264", "h264"), "h265": ("libx265", "hevc")}
#: default VBV buffer, in seconds at the peak rate (the setting that hit the target within
#: 1-2 % in the feasibility measurements).
DEFAULT_BUFFER_S = 0.5


@dataclass
class _Encoded:
    """One stream's coded video: packets in decoding (= presentation) order, pts = dataset index."""

    width: int
    height: int
    packets: list[bytes] = field(default_factory=list)
    pts: list[int] = field(default_factory=list)
    keyframes: list[int] = field(default_factory=list)  # packet numbers of keyframes
    position: dict[int, int] = field(default_factory=dict)  # pts -> packet number

    def bitstream(self) -> bytes:
        return b"".join(self.packets)


class _Cursor:
    """A sequential decoder over one ``_Encoded`` stream that remembers its last picture."""

    def __init__(self, av: Any, decoder: str, encoded: _Encoded, grey: bool):
        self._av, self._decoder_name, self._encoded, self._grey = av, decoder, encoded, grey
        self._context: Any = None
        self._next = 0  # packet number the decoder is fed next
        self._last: tuple[int, np.ndarray] | None = None

    def frame(self, position: int) -> np.ndarray:
        """The decoded picture of packet ``position`` (HxWx3 uint8 RGB)."""
        if self._last is not None and self._last[0] == position:
            return self._last[1]
        keyframes = self._encoded.keyframes
        start = keyframes[max(0, bisect_right(keyframes, position) - 1)] if keyframes else 0
        if self._context is None or position < self._next or start > self._next:
            self._restart(start)
        while self._next <= position:
            packet = self._av.Packet(self._encoded.packets[self._next])
            packet.pts = packet.dts = self._encoded.pts[self._next]
            self._next += 1
            for decoded in self._context.decode(packet):
                self._keep(decoded)
        if self._last is None or self._last[0] != position:  # a decoder delay: drain it
            for decoded in self._context.decode(None):
                self._keep(decoded)
            self._context = None
        if self._last is None or self._last[0] != position:
            raise ModuleError(f"bandwidth: the decoder returned no picture for packet {position}")
        return self._last[1]

    def _restart(self, start: int) -> None:
        self._context = self._av.CodecContext.create(self._decoder_name, "r")
        self._context.thread_count = 1
        self._next = start

    def _keep(self, decoded: Any) -> None:
        position = self._encoded.position[decoded.pts]
        if self._grey:
            luma = decoded.to_ndarray(format="gray")[: self._encoded.height, : self._encoded.width]
            image = np.repeat(luma[..., None], 3, axis=2)
        else:
            image = np.ascontiguousarray(decoded.to_ndarray(format="rgb24")[: self._encoded.height, : self._encoded.width])
        self._last = (position, image)


class Bandwidth(SequencePerturbation):
    """H.264 / H.265 constant-bit-rate coding of each stream at the sequence's frame rate."""

    name = "bandwidth"
    version = 1
    summary = "Video link of limited bandwidth: H.264/H.265 CBR coding (PyAV) at the sequence's fps"

    target_mbps = Param(
        2.0,
        unit="Mbit/s",
        min=0.01,
        max=200.0,
        searchable=True,
        worse="lower",
        doc="bit rate of the link (the encoder's constant target rate)",
    )
    max_mbps = Param(
        None,
        unit="Mbit/s",
        min=0.01,
        max=1000.0,
        optional=True,
        doc="peak rate filling the decoder buffer; None = target_mbps (strict CBR)",
    )
    buffer_mbit = Param(
        None,
        unit="Mbit",
        min=0.001,
        max=1000.0,
        optional=True,
        doc="decoder (VBV) buffer size; None = 0.5 s at the peak rate",
    )
    codec = Param("h264", domain="choice", choices=tuple(CODECS), doc="h264 (libx264) or h265 (libx265)")
    preset = Param("veryfast", domain="choice", choices=PRESETS, doc="encoder speed preset")
    gop_frames = Param(
        None,
        domain="integer",
        unit="frames",
        min=1,
        max=100_000,
        optional=True,
        doc="keyframe interval; None = 2 s of frames",
    )

    def check_params(self, params: dict[str, Any]) -> None:
        if params["max_mbps"] is not None and params["max_mbps"] < params["target_mbps"]:
            raise self.param_error(
                f"max_mbps = {params['max_mbps']:g} Mbit/s is below target_mbps = {params['target_mbps']:g} Mbit/s; "
                "the peak rate must be at least the target rate"
            )

    # -- life cycle ----------------------------------------------------------------------------
    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._av = _import_av()
        encoder, _ = CODECS[self.codec]
        try:
            self._av.codec.Codec(encoder, "w")
        except Exception as exc:
            raise ModuleError(f"bandwidth: this PyAV build has no {encoder} encoder ({exc})") from exc
        self._encoded: dict[str, _Encoded] = {}
        self._cursors: dict[str, _Cursor] = {}
        self._lock = Lock()
        #: measured bit rate (Mbit/s) of each prepared stream: 8 x bytes / T (see the module docs)
        self.measured_mbps: dict[str, float] = {}

    def cleanup(self) -> None:
        self._encoded, self._cursors, self.measured_mbps = {}, {}, {}
        super().cleanup()

    def prepare(self, stream: str, frames: Iterable[tuple[int, np.ndarray]]) -> None:
        """Encode the frames of ``stream`` one by one; only the bit stream is kept."""
        context = self.ready_context()
        encoder: Any = None
        encoded: _Encoded | None = None
        inputs: list[int] = []
        for index, image in frames:
            if encoded is None:
                encoded = _Encoded(width=image.shape[1], height=image.shape[0])
                encoder = self._open_encoder(image.shape[1] + image.shape[1] % 2, image.shape[0] + image.shape[0] % 2)
            elif image.shape[:2] != (encoded.height, encoded.width):
                raise ModuleError(
                    f"bandwidth: frame {index} of {stream} is {image.shape[1]}x{image.shape[0]}, the stream is {encoded.width}x{encoded.height}"
                )
            if inputs and index <= inputs[-1]:
                raise ModuleError(f"bandwidth: frames of {stream} must come in increasing index order (got {index} after {inputs[-1]})")
            picture = self._av.VideoFrame.from_ndarray(_pad_even(image), format="rgb24")
            picture.pts = index
            self._store(encoded, encoder.encode(picture.reformat(format="yuv420p")))
            inputs.append(index)
        if encoded is None:
            encoded = _Encoded(width=0, height=0)
        else:
            self._store(encoded, encoder.encode(None))
        if encoded.pts != inputs:
            raise ModuleError(f"bandwidth: the {len(inputs)} frames of {stream} came back as {len(encoded.pts)} packets or out of order")
        duration = (encoded.pts[-1] - encoded.pts[0] + 1) / context.fps if encoded.pts else 0.0
        self.measured_mbps[stream] = 8 * sum(map(len, encoded.packets)) / duration / 1e6 if duration else 0.0
        self._encoded[stream] = encoded
        self._cursors[stream] = _Cursor(self._av, CODECS[self.codec][1], encoded, grey=context.sequence.grayscale)

    def is_prepared(self, stream: str) -> bool:
        return stream in getattr(self, "_encoded", {})

    def result(self, index: int, stream: str) -> np.ndarray:
        """The decoded frame ``index`` of ``stream`` (sequential access is cheapest)."""
        if not self.is_prepared(stream):
            raise ModuleError(f"bandwidth: stream {stream!r} was not prepared; call prepare({stream!r}, frames) first")
        position = self._encoded[stream].position.get(index)
        if position is None:
            raise ModuleError(f"bandwidth: frame {index} was not among the frames given to prepare({stream!r})")
        with self._lock:
            return self._cursors[stream].frame(position)

    def bitstream(self, stream: str) -> bytes:
        """The coded elementary stream (Annex B) of ``stream``, e.g. to save as ``.h264``."""
        if not self.is_prepared(stream):
            raise ModuleError(f"bandwidth: stream {stream!r} was not prepared")
        return self._encoded[stream].bitstream()

    # -- helpers -------------------------------------------------------------------------------
    def _open_encoder(self, width: int, height: int) -> Any:
        fps = self.ready_context().fps
        encoder, _ = CODECS[self.codec]
        rate = int(round(self.target_mbps * 1e6))
        peak = int(round((self.max_mbps or self.target_mbps) * 1e6))
        buffer = int(round(self.buffer_mbit * 1e6)) if self.buffer_mbit is not None else int(round(peak * DEFAULT_BUFFER_S))
        frame_rate = Fraction(fps).limit_denominator(1001)
        context = self._av.CodecContext.create(encoder, "w")
        context.width, context.height, context.pix_fmt = width, height, "yuv420p"
        context.framerate = frame_rate
        context.time_base = 1 / frame_rate
        context.bit_rate = rate
        context.gop_size = self.gop_frames or max(1, round(2 * fps))
        context.thread_count = 1
        options = {"preset": self.preset, "tune": "zerolatency", "maxrate": str(peak), "bufsize": str(buffer)}
        strict = peak == rate
        if strict:
            options["minrate"] = str(rate)
        if encoder == "libx264":
            options["x264-params"] = f"nal-hrd={'cbr' if strict else 'vbr'}:force-cfr=0"
        else:
            options["x265-params"] = f"{'strict-cbr=1:' if strict else ''}pools=none:frame-threads=1:log-level=error"
        context.options = options
        return context

    @staticmethod
    def _store(encoded: _Encoded, packets: Iterable[Any]) -> None:
        for packet in packets:
            if packet.is_keyframe:
                encoded.keyframes.append(len(encoded.packets))
            encoded.position[int(packet.pts)] = len(encoded.packets)
            encoded.pts.append(int(packet.pts))
            encoded.packets.append(bytes(packet))


def _pad_even(image: np.ndarray) -> np.ndarray:
    """``image`` with one replicated column / row added where width / height is odd (yuv420p)."""
    bottom, right = image.shape[0] % 2, image.shape[1] % 2
    if not (bottom or right):
        return np.ascontiguousarray(image)
    return cv2.copyMakeBorder(image, 0, bottom, 0, right, cv2.BORDER_REPLICATE)


def _import_av() -> Any:
    try:
        import av
    except ImportError as exc:
        raise ModuleError("bandwidth needs PyAV: pip install 'pytest-sal[video]'") from exc
    return av
