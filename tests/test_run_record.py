"""RunRecord, a run's one type: the outcome's JSON form, the cache entry, the verdict."""

from __future__ import annotations

import pickle

from pytest_sal.analysis.aggregation import AGGREGATED
from pytest_sal.engine.outcomes.run_record import RunRecord

METRICS = {name: None for name in AGGREGATED} | {"tracking_rate": 0.5, "failure": None, "starved": True, "wall_time_s": 1.5}


def test_a_run_of_any_history_reads_back_as_it_was_written() -> None:
    for stored in (
        {**METRICS, "passed": True, "abstained": False, "cached": True},
        {**METRICS, "passed": False, "abstained": True, "cached": False, "not_cached": "timed out on a busy machine"},
        {"abstained": True},  # a hand-made run: what it says
        {"tracking_rate": 0.9},  # not judged
    ):
        run = RunRecord.from_dict(stored)
        assert run.to_dict() == stored and list(run.to_dict()) == list(stored) and run == stored
        assert dict(run) == stored and run.get("stopped") is None and ("passed" in run) == ("passed" in stored)
    assert RunRecord.from_dict({"passed": False}).to_dict() == {"passed": False, "abstained": False, "cached": False}  # judged: all three


def test_the_cache_entry_holds_the_run_without_its_verdict() -> None:
    run = RunRecord(METRICS, value=20.0, module={"name": "fog"}, artifacts={"frame": "a.png"}, images={"frame": b"png"})
    entry = run.entry()
    assert entry == {"value": 20.0, "module": {"name": "fog"}, "metrics": METRICS, "artifacts": {"frame": "a.png"}}
    assert RunRecord.entry_problem(entry) is None and RunRecord.from_entry(entry) == run
    assert RunRecord.entry_problem({**entry, "metrics": {**METRICS, "starved": "no"}}) == "metrics.starved is not true or false"
    assert (
        RunRecord.entry_problem({**entry, "metrics": {k: v for k, v in METRICS.items() if k != "matched"}}) == "metrics.matched is missing"
    )


def test_judged_a_starved_failed_run_abstains_and_travels_light() -> None:
    run = RunRecord(METRICS, images={"frame": b"png"}, result={"states": ["ok"]}, worker="host:1")
    failed, held = run.judged(False, cached=False), run.judged(True, cached=True)
    assert failed["abstained"] and not failed["passed"] and not held["abstained"] and held["cached"]
    assert failed.images == {} and failed.result == {} and failed.worker == "host:1"
    assert pickle.loads(pickle.dumps(failed)) == failed  # what a Ray worker sends back
