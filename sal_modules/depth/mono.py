"""Monocular depth from a user-supplied ONNX model (e.g. Depth Anything V2 exported to ONNX).

Mathematical formulation
------------------------
The frame (RGB, values ``I / 255`` in 0..1) is resized to the model input ``H_in x W_in``
(bicubic) and normalised per channel, ``x = (I / 255 - mean_c) / std_c`` (ImageNet statistics
by default), laid out as ``1 x 3 x H_in x W_in`` (or ``1 x H_in x W_in x 3`` when the model
says so). The model's first output ``y`` (one value per pixel) is resized back to the image
size (bilinear) and turned into metres:

- ``output="metric"``: ``Z = scale * y`` (the model predicts depth in metres);
- ``output="inverse"``: ``Z = scale / y`` for ``y > 0`` (the model predicts inverse depth or a
  disparity-like quantity; ``scale`` is the metric factor, e.g. ``f B`` for disparity in px).

Non-finite or non-positive results are 0 (unknown). The cache key holds the model file's
SHA-256, so replacing the model invalidates the cached depth.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from threading import Lock
from typing import Any

import cv2
import numpy as np

from sal_adapters.sequence import Sequence
from sal_modules.depth.base import DepthProvider
from sal_modules.errors import ModuleError

__all__ = ["MonoDepth"]

#: Model input size (H, W) used when the model leaves it open: Depth Anything's 518 px (37 x 14).
DEFAULT_INPUT_SIZE = (518, 518)
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
OUTPUTS = ("metric", "inverse")


class MonoDepth(DepthProvider):
    """Depth of each frame from a monocular ONNX network, on the CPU.

    Args:
        model: path to the ``.onnx`` file.
        input_size: model input ``(height, width)`` in px for models whose input size is
            dynamic; default: the model's own static size, else 518 x 518.
        output: ``"metric"`` (output is depth in m) or ``"inverse"`` (depth = scale / output).
        scale: factor applied to the output (metric) or divided by it (inverse).
        mean, std: per-channel normalisation of the 0..1 RGB input (ImageNet by default).
    """

    name = "mono"
    #: Algorithm version: part of the cache key, bumped when the output changes.
    version = 1

    def __init__(
        self,
        model: str | Path,
        *,
        input_size: tuple[int, int] | None = None,
        output: str = "metric",
        scale: float = 1.0,
        mean: tuple[float, float, float] = IMAGENET_MEAN,
        std: tuple[float, float, float] = IMAGENET_STD,
    ):
        if output not in OUTPUTS:
            raise ModuleError(f"mono depth: output must be one of {', '.join(OUTPUTS)}, got {output!r}")
        if not float(scale) > 0:
            raise ModuleError(f"mono depth: scale must be > 0, got {scale!r}")
        if input_size is not None and (len(input_size) != 2 or min(int(v) for v in input_size) < 1):
            raise ModuleError(f"mono depth: input_size must be (height, width) in px, got {input_size!r}")
        if len(mean) != 3 or len(std) != 3 or min(std) <= 0:
            raise ModuleError("mono depth: mean and std need three values each, std > 0")
        self.model = Path(model).expanduser()
        self.input_size = None if input_size is None else (int(input_size[0]), int(input_size[1]))
        self.output = output
        self.scale = float(scale)
        self.mean = tuple(float(v) for v in mean)
        self.std = tuple(float(v) for v in std)
        self._session: tuple[tuple[int, int] | None, Any] | None = None
        self._digest: tuple[tuple[int, int], str] | None = None
        self._lock = Lock()

    def settings(self) -> dict[str, Any]:
        return {
            "version": self.version,
            "model_sha256": self.model_sha256(),
            "input_size": None if self.input_size is None else list(self.input_size),
            "output": self.output,
            "scale": self.scale,
            "mean": list(self.mean),
            "std": list(self.std),
        }

    def _stamp(self) -> tuple[int, int] | None:
        """Size and modification time of the model file, or ``None`` when it does not exist."""
        try:
            st = self.model.stat()
        except OSError:
            return None
        return (st.st_size, st.st_mtime_ns)

    def model_sha256(self) -> str | None:
        """SHA-256 (hex) of the model file (re-read when the file changes), or ``None`` when
        it does not exist."""
        stamp = self._stamp()
        if stamp is None:
            return None
        if self._digest is None or self._digest[0] != stamp:
            h = hashlib.sha256()
            with self.model.open("rb") as f:
                for chunk in iter(lambda: f.read(1 << 20), b""):
                    h.update(chunk)
            self._digest = (stamp, h.hexdigest())
        return self._digest[1]

    def unavailable(self, sequence: Sequence) -> str | None:
        try:
            self.session()
        except ModuleError as exc:
            return str(exc)
        return None

    def session(self) -> Any:
        """The ONNX Runtime session (CPU), created on first use and again when the file changes.

        Raises:
            ModuleError: onnxruntime is missing, or the model file is missing or not a valid
                ONNX model with one image input.
        """
        with self._lock:
            stamp = self._stamp()
            if self._session is None or self._session[0] != stamp:
                self._session = (stamp, self._open())
            return self._session[1]

    def _open(self) -> Any:
        try:
            import onnxruntime
        except ImportError as exc:
            raise ModuleError("monocular depth needs onnxruntime: pip install 'pytest-sal[onnx]'") from exc
        if not self.model.is_file():
            raise ModuleError(f"monocular depth model {self.model} not found")
        try:
            session = onnxruntime.InferenceSession(str(self.model), providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types for bad files
            raise ModuleError(f"monocular depth model {self.model} is not a valid ONNX model: {exc}") from exc
        shape = session.get_inputs()[0].shape
        if len(session.get_inputs()) != 1 or len(shape) != 4 or 3 not in (shape[1], shape[3]):
            raise ModuleError(
                f"monocular depth model {self.model} must take one 1x3xHxW (or 1xHxWx3) image, its inputs are {[i.shape for i in session.get_inputs()]}"
            )
        return session

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        frame = sequence[position]
        image = frame.right if stream == "right" else frame.image
        if image is None:
            raise ModuleError(f"mono depth: sequence {sequence.name!r} has no right images")
        return self.predict(image)

    def predict(self, image: np.ndarray) -> np.ndarray:
        """Depth (float32 m, 0 = unknown) of one HxWx3 uint8 RGB image."""
        session = self.session()
        model_input = session.get_inputs()[0]
        channels_last = model_input.shape[3] == 3 and model_input.shape[1] != 3
        dims = model_input.shape[1:3] if channels_last else model_input.shape[2:4]
        size = [d if isinstance(d, int) and d > 0 else None for d in dims]
        fallback = self.input_size or DEFAULT_INPUT_SIZE
        height, width = (size[0] or fallback[0], size[1] or fallback[1])
        pixels = cv2.resize(image, (width, height), interpolation=cv2.INTER_CUBIC).astype(np.float32) / 255.0
        normalised = (pixels - np.asarray(self.mean, np.float32)) / np.asarray(self.std, np.float32)
        batch = normalised[None] if channels_last else normalised.transpose(2, 0, 1)[None]
        output = np.asarray(session.run(None, {model_input.name: np.ascontiguousarray(batch, dtype=np.float32)})[0], dtype=np.float32)
        output = np.squeeze(output)
        if output.ndim != 2:
            raise ModuleError(f"monocular depth model {self.model} must output one value per pixel, its output has shape {output.shape}")
        y = cv2.resize(output, (image.shape[1], image.shape[0]), interpolation=cv2.INTER_LINEAR)
        depth: np.ndarray
        if self.output == "metric":
            depth = self.scale * y
        else:
            depth = self.scale / np.where(y > 0, y, np.inf)
        return np.where(np.isfinite(depth) & (depth > 0), depth, 0.0).astype(np.float32)
