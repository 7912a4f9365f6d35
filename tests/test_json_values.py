"""``json_safe``: each documented rule, and JSON that ``allow_nan=False`` accepts."""

from __future__ import annotations

import enum
import json
import math
from pathlib import Path, PurePosixPath

import numpy as np
import pytest

from sal_adapters.common.json_values import json_safe


class Level(enum.IntEnum):
    LOW = 1


def test_json_values_stay_as_they_are() -> None:
    for value in (None, True, False, "text", 0, -7, 2**70, 1.5, Level.LOW):
        assert json_safe(value) is value or json_safe(value) == value
    assert json_safe(True) is True  # not turned into 1


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, np.float64("nan"), np.float32("inf")])
def test_numbers_that_are_not_numbers_become_none(value: float) -> None:
    assert json_safe(value) is None


def test_numpy_scalars_and_arrays_become_python_values() -> None:
    assert json_safe(np.float64(0.25)) == 0.25 and type(json_safe(np.float64(0.25))) is float
    assert json_safe(np.float32(0.5)) == 0.5 and type(json_safe(np.float32(0.5))) is float
    assert json_safe(np.int64(3)) == 3 and type(json_safe(np.int64(3))) is int
    assert json_safe(np.bool_(True)) is True
    assert json_safe(np.array([[1, 2], [3, 4]])) == [[1, 2], [3, 4]]
    assert json_safe(np.array([1.0, np.nan])) == [1.0, None]


def test_paths_become_text() -> None:
    assert json_safe(Path("/tmp/a b/c.json")) == "/tmp/a b/c.json"
    assert json_safe(PurePosixPath("x/y")) == "x/y"


def test_containers_convert_recursively_with_text_keys() -> None:
    value = {1: (np.int64(2), {Path("p"): [math.nan]}), "s": {3, 1, 2}, "mixed": frozenset({"a", 1})}
    assert json_safe(value) == {"1": [2, {"p": [None]}], "s": [1, 2, 3], "mixed": ["a", 1]}
    assert json.loads(json.dumps(json_safe(value), allow_nan=False)) == json_safe(value)


def test_anything_else_is_refused_by_type() -> None:
    with pytest.raises(TypeError, match="cannot write object"):
        json_safe({"x": object()})
