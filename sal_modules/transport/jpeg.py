"""``jpeg``: frames sent as JPEG pictures (a still-image link or a camera's own compression).

Mathematical formulation
------------------------
Baseline JPEG (libjpeg through ``cv2.imencode`` / ``cv2.imdecode``): RGB -> Y'CbCr (BT.601,
full range), chroma subsampled by (h, v) = (1, 1) for 4:4:4, (2, 1) for 4:2:2 or (2, 2) for
4:2:0, 8x8 DCT per block, coefficients quantised as

    q_uv = round(F_uv / Q_uv(s)),   Q_uv(s) = clip(floor((T_uv s + 50) / 100), 1, 255),
    s = 5000 / quality for quality < 50, else 200 - 2 quality,

with T the IJG reference tables (luma and chroma), then decoded again. Lower ``quality``
gives coarser steps: blocking, ringing at edges and, with subsampling, colour bleeding. Grey
datasets are coded as one-channel JPEG, as a grey camera would send them. Deterministic: the
same image always gives the same bytes.
"""

from __future__ import annotations

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError
from sal_modules.params import Param

__all__ = ["Jpeg"]

#: chroma_subsampling -> OpenCV sampling factor.
SAMPLING = {
    "4:4:4": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444,
    "4:2:2": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
    "4:2:0": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
}


class Jpeg(Perturbation):
    """JPEG encode / decode round trip at ``quality`` with the chosen chroma subsampling."""

    name = "jpeg"
    version = 1
    summary = "JPEG compression at a quality level (1..100) with chroma subsampling"

    quality = Param(
        30,
        domain="integer",
        min=1,
        max=100,
        searchable=True,
        worse="lower",
        doc="JPEG quality factor (IJG scale; 100 = finest quantisation)",
    )
    chroma_subsampling = Param("4:2:0", domain="choice", choices=tuple(SAMPLING), doc="chroma subsampling (J:a:b)")

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._grey = context.sequence.grayscale
        self._flags = [cv2.IMWRITE_JPEG_QUALITY, self.quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, SAMPLING[self.chroma_subsampling]]

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        self.ready_context()
        if self._grey:
            ok, data = cv2.imencode(".jpg", np.ascontiguousarray(image[..., 0]), self._flags)
            decoded = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if ok else None
            out = None if decoded is None else cv2.cvtColor(decoded, cv2.COLOR_GRAY2RGB)
        else:
            ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), self._flags)
            decoded = cv2.imdecode(data, cv2.IMREAD_COLOR) if ok else None
            out = None if decoded is None else cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)
        if out is None:
            raise ModuleError(f"jpeg: OpenCV could not encode/decode frame {index} ({stream}) at quality {self.quality}")
        return out
