"""``TrialMetrics``: a trial's metrics read like ``RunMetrics`` (attributes) and like the dict
they were (items), stored and compared as that dict."""

from __future__ import annotations

import copy
import json
import pickle

import pytest

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial, TrialMetrics

STORED = {"ate_rmse": None, "rpe_trans": 0.02, "tracking_rate": 0.9, "maps": 1, "failures": ["lost at frame 12"]}


def trial() -> Trial:
    return Trial(30.0, True, dict(STORED))


def test_attribute_and_item_access_agree_and_a_missing_metric_reads_as_none() -> None:
    metrics = trial().metrics
    assert isinstance(metrics, TrialMetrics)
    assert metrics.tracking_rate == metrics["tracking_rate"] == metrics.get("tracking_rate") == 0.9
    assert metrics.maps == 1 and metrics.failures == ["lost at frame 12"]
    # the system lost tracking: no ATE, whether stored as null or not stored at all
    assert metrics.ate_rmse is None and metrics["ate_rmse"] is None
    assert metrics.scale_error is None and metrics["scale_error"] is None and metrics.get("scale_error") is None
    assert "tracking_rate" in metrics and "scale_error" not in metrics
    assert list(metrics) == list(STORED) and dict(metrics.items()) == STORED and len(metrics) == len(STORED)


def test_an_unknown_metric_names_the_closest_or_lists_the_known_ones() -> None:
    metrics = trial().metrics
    with pytest.raises(AttributeError, match=r"^trial metrics have no 'tracking_rte'; did you mean 'tracking_rate'\?$"):
        metrics.tracking_rte
    with pytest.raises(KeyError, match=r"trial metrics have no 'atermse'; did you mean 'ate_rmse'\?"):
        metrics["atermse"]
    with pytest.raises(
        AttributeError,
        match=r"trial metrics have no 'xyz'; metrics: ate_rmse, rpe_trans, rpe_rot, t_rel, r_rel, tracking_rate, .*, failures$",
    ):
        metrics.xyz
    assert metrics.get("xyz") is None and not hasattr(metrics, "xyz") and not hasattr(metrics, "_private")


def test_equal_to_the_dict_json_and_history_unchanged() -> None:
    metrics = trial().metrics
    assert metrics == STORED and metrics == STORED and metrics != {**STORED, "maps": 2}
    assert json.loads(json.dumps(metrics)) == STORED
    outcome = Outcome(
        "t.py::test_x[fog.visibility_m=30]",
        "fake",
        "urban",
        "fog.visibility_m",
        "lower",
        None,
        "r",
        "passed",
        Boundary(30.0, None, "m"),
        "single",
        [trial()],
    )
    data = outcome.to_dict()
    assert type(data["trials"][0]["metrics"]) is dict and data["trials"][0]["metrics"] == STORED
    again = Outcome.from_dict(json.loads(json.dumps(data)))
    assert again == outcome and again.trials[0].metrics.tracking_rate == 0.9


def test_read_only_with_copies_that_keep_the_type() -> None:
    metrics = trial().metrics
    for change in (
        lambda m: m.__setitem__("maps", 2),
        lambda m: m.update(maps=2),
        lambda m: m.pop("maps"),
        lambda m: m.setdefault("x", 1),
        lambda m: m.clear(),
    ):
        with pytest.raises(TypeError, match="read-only"):
            change(metrics)
    assert metrics == STORED
    for other in (copy.copy(metrics), copy.deepcopy(metrics), pickle.loads(pickle.dumps(metrics))):
        assert type(other) is TrialMetrics and other == STORED
    changed = trial()
    changed.metrics = {**changed.metrics, "maps": 2}  # assigning a dict wraps it
    assert changed.metrics.maps == 2 and isinstance(changed.metrics, TrialMetrics)
