"""The example experiment configs in ``example_suites/configs/`` (the paper's table of severities):
the table is complete, each one loads and exercises its modules, and each names a searchable
robustness boundary."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from example_config_table import CONFIGS, GRADES, MODULES, NAMES, ORIGINAL, REQUIRED, WORLD, _groups, _real_kind, _steps

from pytest_sal.experiment.config import load_config
from pytest_sal.experiment.schema import build_module
from sal_modules import Composite

# ------------------------------------------------------------------------------ 1. the files


def test_the_table_is_complete() -> None:
    missing = sorted(set(REQUIRED + ORIGINAL) - set(NAMES))
    assert not missing, f"example configs missing from {CONFIGS}: {missing}"


@pytest.mark.parametrize("name", NAMES)
def test_config_loads(name: str) -> None:
    config = load_config(CONFIGS / name)
    assert config.experiment.name == Path(name).stem
    ds = config.dataset
    assert ds.type == "synthetic" and ds.path is None
    assert name in WORLD, f"{name}: add it to WORLD (and to the real-data pairing) in this test"
    scene, sensor = WORLD[name]
    assert ds.options["scene"] == scene
    assert ds.options.get("sensor", "stereo" if scene == "urban" else "rgbd") == sensor
    assert ds.max_frames == 20 and ds.options["frames"] == 20
    assert config.output.base_dir == Path("results") and not config.output.create_timestamp_dir
    text = (CONFIGS / name).read_text()
    for command in ("perturb", "evaluate", "boundary", "features"):
        assert f"#   sal {command} example_suites/configs/{name}" in text, f"{name}: header lacks the sal {command} line"
    kind = _real_kind(name)
    assert re.search(rf"# real data: type: {kind}, path: /data/", text), (
        f"{name}: dataset block lacks the '# real data: type: {kind}' comment"
    )
    if name in REQUIRED:
        names = [p.name for p in config.enabled()]
        groups = _groups(config)
        assert len(groups) == 1 and len(names) == 3, f"{name}: expected one light/moderate/heavy group, got {names}"
        (grades,) = groups.values()
        assert set(grades) == set(GRADES)
        for pert in names:
            assert _steps(config, pert) == MODULES[name]


# ------------------------------------------------------------------------------ 2. the boundary


@pytest.mark.parametrize("name", NAMES)
def test_robustness_boundary_is_searchable(name: str) -> None:
    config = load_config(CONFIGS / name)
    rb = config.robustness_boundary
    assert rb is not None and rb.enabled, f"{name}: robustness_boundary must be present and enabled"
    target = next(p for p in config.perturbations if p.name == rb.target_perturbation)
    assert target.enabled and target.type != "none"
    module = build_module(target)
    if isinstance(module, Composite):
        step, _, param = rb.parameter.partition(".")
        assert param, f"{name}: a composite's parameter is addressed <step>.<param>, got {rb.parameter!r}"
        position, spec = module.param(rb.parameter)
        assert module.steps[position].name == step == rb.module
    else:
        assert "." not in rb.parameter
        spec = type(module).parameters()[rb.parameter]
        assert rb.module == module.name == target.type
    assert spec.searchable
    space = spec.search_space()
    assert space.min <= rb.lower_bound < rb.upper_bound <= space.max
    assert 0 < rb.tolerance < rb.upper_bound - rb.lower_bound
    assert 6 <= rb.max_trials <= 8
    assert rb.ate_rmse_fail > 0
    assert rb.name
