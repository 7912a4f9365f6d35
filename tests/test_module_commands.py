"""``sal modules`` and ``sal preview`` end to end."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from test_perturb import Square

from pytest_sal.cli.main import main
from sal_adapters.images import read_image
from sal_modules import PERTURBATIONS


@pytest.fixture(autouse=True)
def square() -> Iterator[None]:
    PERTURBATIONS.register(Square.name, Square)
    yield
    PERTURBATIONS.unregister(Square.name)


def test_modules_lists_parameters_with_units_and_directions(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["modules", "test_square"]) == 0
    out = capsys.readouterr().out
    assert "test_square (v1): test: black square" in out
    assert "size" in out and "0 .. 1000 px" in out and "searchable, worse when higher" in out


def test_modules_with_a_misspelt_name_suggests_the_closest(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["modules", "fgo"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sal: error: unknown perturbation module 'fgo'; did you mean 'fog'?") and err.count("\n") == 1


def test_preview_writes_original_and_perturbed_side_by_side(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "p.png"
    assert (
        main(
            [
                "preview",
                "test_square",
                "size=50",
                "value=255",
                "--dataset",
                "synthetic",
                "--dataset-option",
                "scene=indoor",
                "--frame",
                "1",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert "frame 1 of synthetic/indoor-seed0: kept" in capsys.readouterr().out
    sheet = read_image(out)
    assert sheet.shape == (28 + 480, 640 * 2 + 8, 3)  # title bar, one stream (RGB-D), two tiles
    left, right = sheet[28:, :640], sheet[28:, 648:]
    assert (right[:50, :50] == 255).all() and not (left[:50, :50] == 255).all()
    np.testing.assert_array_equal(left[60:], right[60:])


def test_preview_of_a_chain_with_addressed_parameters(tmp_path: Path) -> None:
    out = tmp_path / "chain.png"
    assert (
        main(
            [
                "preview",
                "frame_drop>>test_square",
                "mode=periodic",
                "period=2",
                "size=5",
                "--dataset",
                "synthetic",
                "--frame",
                "1",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    sheet = read_image(out)  # urban stereo: two rows; frame 1 is dropped (every 2nd frame)
    assert sheet.shape == (28 + 376 * 2 + 8, 1240 * 2 + 8, 3)
    dropped = sheet[28:404, 1248:]
    assert np.median(dropped) == 96 and (dropped == 255).any()  # grey tile with "frame dropped" written on it


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["preview", "nosuch", "--dataset", "synthetic"], "unknown perturbation module 'nosuch'"),
        (["preview", "fgo", "--dataset", "synthetic"], "unknown perturbation module 'fgo'; did you mean 'fog'?"),
        (["preview", "night>>fgo", "--dataset", "synthetic"], "unknown perturbation module 'fgo'; did you mean 'fog'?"),
        (
            ["preview", "night>>fog", "fog.visibilty_m=30", "--dataset", "synthetic"],
            "has no parameter 'fog.visibilty_m'; did you mean 'fog.visibility_m'?",
        ),
        (
            ["preview", "test_square", "size=-1", "--dataset", "synthetic"],
            "test_square: size = -1 px is not valid; size must be an integer in 0 .. 1000 px",
        ),
        (["preview", "test_square", "sise=3", "--dataset", "synthetic"], "did you mean 'size'?"),
        (["preview", "test_square", "size", "--dataset", "synthetic"], "a module parameter expects KEY=VALUE, got 'size'"),
        (["preview", "test_square", "--dataset", "synthetic", "--dataset-option", "frames=3", "--frame", "9"], "past the end"),
    ],
)
def test_preview_bad_input_is_one_clear_error(argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*argv, "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sal: error: ") and message in err and err.count("\n") == 1
    assert not (tmp_path / "x.png").exists()
