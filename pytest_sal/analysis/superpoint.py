"""SuperPoint keypoints and descriptors from a user-supplied ONNX model (onnxruntime, CPU).

The standard SuperPoint export takes a grey image ``1 x 1 x H x W`` float32 in [0, 1] and returns
``semi`` (``1 x 65 x H/8 x W/8`` detector logits, channel 64 the "no keypoint" dustbin) and
``desc`` (``1 x D x H/8 x W/8`` coarse descriptors, D = 256). Inputs and outputs may be named
differently: the first input is fed and the two outputs are told apart by shape (65 channels is
``semi``). Decoding: softmax over the 65 channels, drop the dustbin, depth-to-space to an H x W
heatmap, threshold, non-maximum suppression, top-k, bilinear sampling of the coarse descriptors
at the keypoints, L2 normalisation.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from sal_adapters.common.errors import SalError

__all__ = ["SuperPointExtractor", "decode_superpoint"]

CELL = 8  # pixels per coarse cell
BORDER = 4  # keypoints this close to the image border are dropped (as in the original)
EXPECTED = "a 1x65x(H/8)x(W/8) detector output ('semi') and a 1xDx(H/8)x(W/8) descriptor output ('desc')"


class SuperPointExtractor:
    """SuperPoint features from the ONNX model at ``model_path``.

    Args:
        model_path: a SuperPoint ONNX file (see the module docstring for what it must look like).
        max_keypoints: keep at most this many keypoints, the highest scoring first.
        threshold: minimum keypoint probability (heatmap value).
        nms_px: non-maximum suppression radius (pixels).
        ratio: nearest/second-nearest distance ratio a match must stay under (``None``: mutual
            nearest neighbours only).
    """

    name = "superpoint"

    def __init__(
        self, model_path: str | Path, max_keypoints: int = 1000, threshold: float = 0.015, nms_px: int = 4, ratio: float | None = 0.9
    ):
        self.model_path = Path(model_path)
        self.max_keypoints = int(max_keypoints)
        self.threshold = float(threshold)
        self.nms_px = int(nms_px)
        self.ratio = ratio
        if not self.model_path.is_file():
            raise SalError(f"{self.model_path}: SuperPoint model file not found (expected an ONNX file with {EXPECTED})")
        try:
            import onnxruntime as ort
        except ImportError as exc:  # pragma: no cover - optional dependency
            raise SalError(f"SuperPoint needs onnxruntime (pip install onnxruntime) to run {self.model_path}") from exc
        options = ort.SessionOptions()
        options.log_severity_level = 3
        try:
            self._session = ort.InferenceSession(str(self.model_path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise SalError(f"{self.model_path}: cannot load the SuperPoint model ({type(exc).__name__}: {exc})") from exc
        inputs = self._session.get_inputs()
        outputs = self._session.get_outputs()
        if not inputs or len(outputs) < 2:
            raise SalError(
                f"{self.model_path}: a SuperPoint model needs one image input and two outputs: {EXPECTED}; it has {len(inputs)} input(s) and {len(outputs)} output(s)"
            )
        self._input = inputs[0]
        shape = list(self._input.shape)
        self._channels = shape[1] if len(shape) == 4 and isinstance(shape[1], int) else 1
        self._fixed_size = tuple(shape[2:]) if len(shape) == 4 and all(isinstance(s, int) for s in shape[2:]) else None

    def __repr__(self) -> str:
        return f"SuperPointExtractor({str(self.model_path)!r}, max_keypoints={self.max_keypoints}, threshold={self.threshold}, nms_px={self.nms_px})"

    def detect(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keypoints (``N x 2`` float32 pixels, x then y) and unit descriptors (``N x D`` float32)
        of a grey image (uint8, or float in [0, 1])."""
        image = np.asarray(grey)
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        image = image.astype(np.float32) / 255.0 if image.dtype == np.uint8 else image.astype(np.float32)
        h, w = image.shape
        padded = cv2.copyMakeBorder(image, 0, -h % CELL, 0, -w % CELL, cv2.BORDER_REPLICATE)
        if self._fixed_size is not None and padded.shape != self._fixed_size:
            raise SalError(
                f"{self.model_path}: the model takes {self._fixed_size[0]}x{self._fixed_size[1]} images, got {h}x{w} (padded to {padded.shape[0]}x{padded.shape[1]})"
            )
        batch = np.repeat(padded[None, None], self._channels, axis=1)
        try:
            results = self._session.run(None, {self._input.name: batch})
        except Exception as exc:
            raise SalError(
                f"{self.model_path}: the SuperPoint model failed on a {padded.shape[0]}x{padded.shape[1]} image ({type(exc).__name__}: {exc})"
            ) from exc
        semi, desc = self._pick_outputs(results, padded.shape)
        return decode_superpoint(semi, desc, (h, w), self.threshold, self.nms_px, self.max_keypoints)

    def match(self, d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
        """Mutual nearest neighbours in L2 distance with a ratio test: ``M x 2`` index pairs."""
        if not len(d1) or not len(d2):
            return np.zeros((0, 2), dtype=np.int64)
        similarity = np.asarray(d1, np.float32) @ np.asarray(d2, np.float32).T
        nn12 = similarity.argmax(axis=1)
        nn21 = similarity.argmax(axis=0)
        rows = np.arange(len(d1))
        keep = nn21[nn12] == rows
        if self.ratio is not None and similarity.shape[1] > 1:
            top2 = -np.partition(-similarity, 1, axis=1)[:, :2]
            dist = np.sqrt(np.maximum(2.0 - 2.0 * top2, 0.0))
            keep &= dist[:, 0] < self.ratio * dist[:, 1]
        return np.column_stack([rows[keep], nn12[keep]]).astype(np.int64)

    def _pick_outputs(self, results: list[np.ndarray], padded: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        arrays = [np.asarray(r)[None] if np.ndim(r) == 3 else np.asarray(r) for r in results]
        cells = (padded[0] // CELL, padded[1] // CELL)
        shapes = ", ".join("x".join(map(str, np.shape(r))) for r in results)
        semi_at = [i for i, a in enumerate(arrays) if a.ndim == 4 and a.shape[0] == 1 and a.shape[1] == 65 and a.shape[2:] == cells]
        if not semi_at:
            raise SalError(
                f"{self.model_path}: expected {EXPECTED} for a {padded[0]}x{padded[1]} image (so {cells[0]}x{cells[1]} cells); the model returned {shapes}"
            )
        semi = arrays[semi_at[0]]
        rest = [
            a for i, a in enumerate(arrays) if i != semi_at[0] and a.ndim == 4 and a.shape[0] == 1 and a.shape[2] >= 1 and a.shape[3] >= 1
        ]
        if not rest:
            raise SalError(f"{self.model_path}: expected {EXPECTED}; found no 1xDxhxw descriptor output among {shapes}")
        return semi[0], rest[0][0]


def decode_superpoint(
    semi: np.ndarray, desc: np.ndarray, size: tuple[int, int], threshold: float = 0.015, nms_px: int = 4, max_keypoints: int = 1000
) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints (``N x 2`` x, y) and unit descriptors (``N x D``) from the raw outputs
    ``semi`` (``65 x Hc x Wc``) and ``desc`` (``D x Hd x Wd``) of an image of ``size`` (h, w)."""
    semi = np.asarray(semi, dtype=np.float32)
    _, hc, wc = semi.shape
    exp = np.exp(semi - semi.max(axis=0, keepdims=True))
    prob = exp[:64] / exp.sum(axis=0, keepdims=True)
    heat = prob.reshape(CELL, CELL, hc, wc).transpose(2, 0, 3, 1).reshape(hc * CELL, wc * CELL)
    heat = np.ascontiguousarray(heat[: size[0], : size[1]])
    ys, xs, scores = _nms(heat, threshold, nms_px)
    inside = (xs >= BORDER) & (xs < size[1] - BORDER) & (ys >= BORDER) & (ys < size[0] - BORDER)
    ys, xs, scores = ys[inside], xs[inside], scores[inside]
    order = np.argsort(-scores, kind="stable")[: max(max_keypoints, 0)]
    keypoints = np.column_stack([xs[order], ys[order]]).astype(np.float32)
    return keypoints, _sample_descriptors(np.asarray(desc, dtype=np.float32), keypoints, size)


def _nms(heat: np.ndarray, threshold: float, radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local maxima of ``heat`` over a (2r+1)^2 window that reach ``threshold``; ties on a
    plateau are resolved greedily (highest score, then raster order, wins)."""
    if radius <= 0:
        ys, xs = np.nonzero(heat >= threshold)
        return ys, xs, heat[ys, xs]
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    peaks = (heat >= threshold) & (heat >= cv2.dilate(heat, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0.0))
    ys, xs = np.nonzero(peaks)
    scores = heat[ys, xs]
    order = np.argsort(-scores, kind="stable")
    ys, xs, scores = ys[order], xs[order], scores[order]
    # candidates closer than the radius are equal maxima: keep the first of each group
    taken = np.zeros(heat.shape, dtype=bool)
    keep = np.zeros(len(ys), dtype=bool)
    for i, (y, x) in enumerate(zip(ys, xs)):
        if taken[y, x]:
            continue
        keep[i] = True
        taken[max(y - radius, 0) : y + radius + 1, max(x - radius, 0) : x + radius + 1] = True
    return ys[keep], xs[keep], scores[keep]


def _sample_descriptors(desc: np.ndarray, keypoints: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Bilinear samples of ``desc`` (``D x Hd x Wd``) at ``keypoints`` (pixels of an image of
    ``size``), cell centres at ``(i + 0.5) * cell - 0.5``, L2-normalised."""
    d, hd, wd = desc.shape
    if not len(keypoints):
        return np.zeros((0, d), dtype=np.float32)
    sy = (size[0] + (-size[0] % CELL)) / hd
    sx = (size[1] + (-size[1] % CELL)) / wd
    u = np.clip((keypoints[:, 0] + 0.5) / sx - 0.5, 0, wd - 1)
    v = np.clip((keypoints[:, 1] + 0.5) / sy - 0.5, 0, hd - 1)
    x0 = np.minimum(np.floor(u).astype(np.int64), max(wd - 2, 0))
    y0 = np.minimum(np.floor(v).astype(np.int64), max(hd - 2, 0))
    x1, y1 = np.minimum(x0 + 1, wd - 1), np.minimum(y0 + 1, hd - 1)
    fx, fy = (u - x0)[None], (v - y0)[None]
    out = (
        desc[:, y0, x0] * (1 - fx) * (1 - fy)
        + desc[:, y0, x1] * fx * (1 - fy)
        + desc[:, y1, x0] * (1 - fx) * fy
        + desc[:, y1, x1] * fx * fy
    ).T
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return (out / np.maximum(norm, 1e-12)).astype(np.float32)
