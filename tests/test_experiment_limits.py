"""Config limits are checked before the work (issue 23, item 10): a config file that is not
regular or over 1 MB is refused before it is read, a long YAML list stops at the value limit
while it is composed, huge numbers are one error naming the key before anything is rendered,
and a dry run holds no image-sized buffer per composite step. Costs are asserted on memory
(tracemalloc's peak), never on a clock."""

from __future__ import annotations

import os
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import yaml
from experiment_configs import base_config, error_of, write

from pytest_sal.cli.main import main
from pytest_sal.experiment.config import ConfigError, load_config
from pytest_sal.experiment.perturb import plan_perturbations

MB = 2**20


@contextmanager
def peak_memory() -> Iterator[list[int]]:
    """``with peak_memory() as peak:`` then ``peak[0]``: the most bytes Python held at once in the block."""
    peak = [0]
    tracemalloc.start()
    try:
        yield peak
    finally:
        peak[0] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()


def _fifo(tmp_path: Path) -> Path:
    path = tmp_path / "fifo.yaml"
    os.mkfifo(path)  # no writer: reading it would wait forever
    return path


@pytest.mark.parametrize(
    ("make", "kind"),
    [(_fifo, "a FIFO"), (lambda tmp_path: Path("/dev/zero"), "a character device"), (lambda tmp_path: tmp_path, "a folder")],
    ids=["fifo", "dev-zero", "folder"],
)
def test_a_config_that_is_not_a_regular_file_is_refused_before_it_is_read(
    tmp_path: Path, make: Callable[[Path], Path], kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = make(tmp_path)

    assert main(["perturb", str(path), "--dry-run"]) == 2

    assert capsys.readouterr().err.splitlines()[-1] == f"sal: error: {path}: is {kind}, not a regular file; give the config's YAML file"


def test_a_config_over_the_size_limit_is_refused_before_it_is_read(tmp_path: Path) -> None:
    path = tmp_path / "big.yaml"
    with path.open("wb") as file:
        file.truncate(64 * MB)  # sparse: nothing on disk, 64 MB to read

    with peak_memory() as peak, pytest.raises(ConfigError) as caught:
        load_config(path)

    assert str(caught.value) == f"{path}: the config is {64 * MB} bytes; the limit is 1000000 bytes"
    assert peak[0] < MB  # neither read nor decoded


def test_a_long_flow_list_stops_at_the_value_limit_while_it_is_composed(tmp_path: Path) -> None:
    text = yaml.safe_dump(base_config(tmp_path), sort_keys=False)
    text += "extra: [" + ", ".join(["1"] * 330_000) + "]\n"  # 998 kB
    assert len(text) < 1_000_000

    with peak_memory() as peak:
        message = error_of(tmp_path, text)

    assert message.endswith("holds more than 20000 values; a config needs a few hundred"), message
    assert peak[0] < 40 * MB  # 330 000 nodes composed took 200 MB


NINES = "9" * 4000  # a YAML int: Python reads 4000 digits, then float() of it overflows
HEX = "0x" + "f" * 5000  # a YAML hex int: beyond Python's 4300-digit limit as decimal


@pytest.mark.parametrize(
    ("key", "literal", "message"),
    [
        (
            ("perturbations", 1, "parameters", "visibility_m"),
            NINES,
            "perturbations[1].parameters.visibility_m: <an integer of about 4001 digits> m is not valid; "
            "visibility_m must be a number in 1 .. 100000 m",
        ),
        (
            ("robustness_boundary", "tolerance"),
            NINES,
            "robustness_boundary.tolerance: <an integer of about 4001 digits> is not valid; must be a number",
        ),
        (
            ("experiment", "seed"),
            HEX,
            "experiment.seed: <an integer of about 6021 digits> is not valid; must be an integer >= 0 and <= 9223372036854775807",
        ),
        (
            ("experiment", "seed"),
            str(2**63),
            "experiment.seed: 9223372036854775808 is not valid; must be an integer >= 0 and <= 9223372036854775807",
        ),
        (
            ("dataset", "start"),
            HEX,
            "dataset.start: <an integer of about 6021 digits> is not valid; must be an integer >= 0 and <= 9223372036854775807",
        ),
    ],
    ids=["4000-digit-visibility", "4000-digit-tolerance", "5000-hex-digit-seed", "seed-2**63", "hex-start"],
)
def test_huge_numbers_are_one_error_naming_the_key_before_anything_is_written(
    tmp_path: Path, key: tuple[Any, ...], literal: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    config = base_config(tmp_path)
    parent = config
    for part in key[:-1]:
        parent = parent[part]
    parent[key[-1]] = "HUGE"
    path = write(tmp_path, yaml.safe_dump(config, sort_keys=False).replace("HUGE", literal))

    assert main(["perturb", str(path), "--cache-dir", str(tmp_path / "cache")]) == 2

    err = capsys.readouterr().err
    assert "Traceback" not in err and err.splitlines()[-1] == f"sal: error: {path}: {message}", err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()  # nothing rendered


def _cracked(tmp_path: Path, steps: int) -> Path:
    config = base_config(tmp_path, robustness_boundary=None)
    config["dataset"] = {"type": "synthetic", "options": {"scene": "urban", "frames": 2, "sensor": "stereo"}}
    config["perturbations"] = [{"name": "c", "type": "composite", "parameters": {"modules": [{"type": "cracked_lens"}] * steps}}]
    return write(tmp_path, config, f"cracked-{steps}.yaml")


def test_a_dry_run_holds_no_buffer_per_composite_step(tmp_path: Path) -> None:
    """32 steps of cracked_lens on a stereo sequence held 580 MB of crack patterns (255: 4.8 GB)."""
    peaks = {}
    for steps in (1, 32):
        config = load_config(_cracked(tmp_path, steps))
        with peak_memory() as peak:
            plan = plan_perturbations(config, dry_run=True)
        peaks[steps] = peak[0]
        assert len(plan.sequences["c"]) == 2
        del plan

    assert peaks[32] - peaks[1] < 4 * MB, peaks
