"""Tiny ONNX models built in tests (no downloads): image -> depth and image -> image.

Every model takes one float32 image ``1 x 3 x H x W`` named ``image``; ``H`` and ``W`` are
dynamic unless ``size=(H, W)`` fixes them. ONNX Runtime 1.31 loads IR version <= 10, so models
are written with ``ir_version = 10`` and opset 17.

>>> path = depth_model(tmp_path / "d.onnx", gain=2.0, offset=1.0)   # depth = 2 * mean_c(x) + 1
>>> path = image_model(tmp_path / "i.onnx", gain=0.5)               # out = 0.5 * x
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

__all__ = ["depth_model", "image_model", "write_onnx_model"]

IR_VERSION = 10
OPSET = 17


def write_onnx_model(
    path: Path,
    nodes: list[onnx.NodeProto],
    outputs: list[onnx.ValueInfoProto],
    size: tuple[int, int] | None = None,
    initializers: dict[str, float] | None = None,
) -> Path:
    """Check and save a one-input model: input ``image`` (``1 x 3 x H x W`` float32), the
    given ``nodes`` and ``outputs``; ``initializers`` become float32 scalar constants."""
    h, w = size if size is not None else ("H", "W")
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, h, w])
    inits = [numpy_helper.from_array(np.array(v, dtype=np.float32), name) for name, v in (initializers or {}).items()]
    graph = helper.make_graph(nodes, "tiny", [image], outputs, initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], ir_version=IR_VERSION)
    onnx.checker.check_model(model)
    path = Path(path)
    onnx.save(model, str(path))
    return path


def depth_model(path: Path, gain: float = 1.0, offset: float = 0.0, size: tuple[int, int] | None = None) -> Path:
    """``depth = gain * mean over channels of image + offset``, shape ``1 x 1 x H x W``
    (``gain=0`` gives a constant)."""
    h, w = size if size is not None else ("H", "W")
    nodes = [
        helper.make_node("ReduceMean", ["image"], ["mean"], axes=[1], keepdims=1),
        helper.make_node("Mul", ["mean", "gain"], ["scaled"]),
        helper.make_node("Add", ["scaled", "offset"], ["depth"]),
    ]
    out = helper.make_tensor_value_info("depth", TensorProto.FLOAT, [1, 1, h, w])
    return write_onnx_model(path, nodes, [out], size, {"gain": gain, "offset": offset})


def image_model(path: Path, gain: float = 1.0, offset: float = 0.0, size: tuple[int, int] | None = None) -> Path:
    """``out = gain * image + offset`` per channel, shape ``1 x 3 x H x W`` (image to image)."""
    h, w = size if size is not None else ("H", "W")
    nodes = [helper.make_node("Mul", ["image", "gain"], ["scaled"]), helper.make_node("Add", ["scaled", "offset"], ["out"])]
    out = helper.make_tensor_value_info("out", TensorProto.FLOAT, [1, 3, h, w])
    return write_onnx_model(path, nodes, [out], size, {"gain": gain, "offset": offset})
