"""Calibration by simulation: does the reliability search state what is true?

Bernoulli systems with a known p(severity) (no SLAM: the search and the fit are what is
measured) on lens_soiling.particles' range, 0..1000 particles, edge 100, R = 0.8, C = 0.9,
max_runs = 30 (the defaults), each over N seeded sessions:

- logistic: p = expit(-(v - 600) / 50);
- plateau: p = 1 - 0.5 expit((v - 650) / 80), falling to 0.5 like ORB-SLAM3 under soiling;
- step: p = 1 below 620.3 particles, else 0 (a deterministic cliff).

Per truth: how often the stated 90 % interval of s80 covers the true s80, how often the
one-sided bound s80/90 lies on the mild side of it (both should be at least C - 2 %), the
verdicts, and the runs. Against it, the votes it replaced, simulated here (``vote_bisection``:
bisection, a trial is a vote of runs until one verdict leads by 2, at most 5, the edge and the
bracket's ends confirmed to a lead of 3, at most 7): how often the bracket holds the true s80
and s50, its runs, and how far apart two sessions' brackets lie. Then the gate: unchanged
sessions compared pairwise against a baseline (false alarms of boundary:10 %), and sessions of
a system whose s80 moved 20 % toward the mild side (detections).

Usage: python benchmarks/bench_reliability.py [--sessions 500] [--processes 2] [--truths step ...]
(``--truths``: only these truths, their votes and the gate pairs among them.)
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from multiprocessing import Pool

import numpy as np
from scipy import special

from pytest_sal.engine.search.bisection import SearchSpace
from pytest_sal.engine.search.reliability_compare import regression_probability
from pytest_sal.engine.search.reliability_curve import SeverityAxis, fit_curve
from pytest_sal.engine.search.reliability_search import reliability_search

R, C, MAX_RUNS, EDGE = 0.8, 0.9, 30, 100.0
AXIS = SeverityAxis.for_range(0, 1000, False, 0.05, integer=True)
TRUTHS: dict[str, Callable[[float], float]] = {
    "logistic": lambda v: float(special.expit(-(v - 600) / 50)),
    "plateau": lambda v: float(1 - 0.5 * special.expit((v - 650) / 80)),
    "step": lambda v: float(v < 620.3),
    "logistic, s80 20 % milder": lambda v: float(special.expit(-(v - 600 * 0.8) / 50)),
}


def true_s(name: str, r: float) -> float:
    values = np.linspace(0, 1000, 200001)
    held = np.array([TRUTHS[name](v) for v in values]) >= r
    return float(values[held].max()) if held.any() else float("nan")


def reliability_session(args: tuple[str, int]) -> tuple:
    """One seeded session of the reliability search: verdict, s80 interval and bound, runs, and
    the runs themselves (for the gate)."""
    name, seed = args
    rng = np.random.default_rng(seed)
    truth = TRUTHS[name]
    result = reliability_search(
        lambda values: [bool(rng.random() < truth(v)) for v in values], AXIS, EDGE, R, C, MAX_RUNS, rel_tolerance=0.1
    )
    value = lambda x: float(AXIS.to_value(min(max(x, 0.0), 1.0)))
    runs = [(o.value, bool(o.held)) for o in result.observations]
    return result.verdict, value(result.s_r.low), value(result.s_r.high), value(result.s_r.bound), result.runs, runs


class VoteTrial:
    """A trial of the votes: runs of a Bernoulli system at ``value``, drawn from ``rng``."""

    def __init__(self, value: float, truth: Callable[[float], float], rng: np.random.Generator, spent: list[int]):
        self.value, self.truth, self.rng, self.spent = value, truth, rng, spent
        self.passes = self.fails = 0
        self.passed = False

    def extend(self, lead: int, cap: int) -> bool:
        """Runs until one verdict leads by ``lead`` or ``cap`` runs are spent; the verdict."""
        while (self.passes + self.fails == 0 or abs(self.passes - self.fails) < lead) and self.passes + self.fails < cap:
            held = self.rng.random() < self.truth(self.value)
            self.passes += held
            self.fails += not held
            self.spent[0] += 1
        self.passed = self.passes > self.fails
        return self.passed


def vote_bisection(
    trial: Callable[[float], VoteTrial], space: SearchSpace, edge: float, rel_tolerance: float, max_trials: int
) -> tuple[float | None, float | None, bool, bool]:
    """The votes, sequentially (the bisection pytest-sal ran for noisy systems before the
    reliability search): a trial votes to a lead of 2 (at most 5 runs); the edge, a far end that
    agrees with it and the final bracket's ends are confirmed to a lead of 3 (at most 7); when
    a confirmation turns an end, bisection goes on in the rebuilt bracket while trials are left.
    ``(pass_value, fail_value, edge_passed, flaky)``; flaky: the edge never led by 2."""
    trials: list[VoteTrial] = []

    def run(value: float) -> VoteTrial:
        trials.append(trial(value))
        trials[-1].extend(2, 5)
        return trials[-1]

    def bracket() -> tuple[float | None, float | None]:
        passing: float | None = None
        failing: float | None = None
        worse = space.worse
        for t in trials:
            if t.passed and (passing is None or worse(t.value, passing)) and (failing is None or worse(failing, t.value)):
                passing = t.value
            if not t.passed and (failing is None or worse(failing, t.value)) and (passing is None or worse(t.value, passing)):
                failing = t.value
        return passing, failing

    first = run(edge)
    first.extend(3, 7)
    flaky = abs(first.passes - first.fails) < 2
    far = space.severe if first.passed else space.mild
    if None in bracket() and len(trials) < max_trials and all(t.value != far for t in trials) and run(far).passed == first.passed:
        trials[-1].extend(3, 7)  # "never failed/passed" is a claim to confirm
    while True:
        passing, failing = bracket()
        if passing is None or failing is None:
            break
        while True:  # bisect to the tolerance, the integer resolution or the budget
            passing, failing = bracket()
            assert passing is not None and failing is not None
            mid = space.midpoint(passing, failing)
            width = abs(passing - failing)
            if width <= rel_tolerance * max(abs(passing), abs(failing)) or space.neighbours(passing, failing):
                break
            if len(trials) >= max_trials or not min(passing, failing) < mid < max(passing, failing):
                break
            run(mid)
        ends = [next(t for t in reversed(trials) if t.value == value) for value in bracket()]
        before = [t.passed for t in ends]
        for t in ends:
            t.extend(3, 7)
        if [t.passed for t in ends] == before or len(trials) >= max_trials:
            break
    passing, failing = bracket()
    return passing, failing, first.passed, flaky


def vote_session(args: tuple[str, int]) -> tuple:
    """One seeded session of the votes: the bracket and the runs."""
    name, seed = args
    rng = np.random.default_rng(10_000 + seed)
    spent = [0]
    space = SearchSpace(mild=0.0, severe=1000.0, domain="integer")
    passing, failing, edge_passed, flaky = vote_bisection(
        lambda value: VoteTrial(value, TRUTHS[name], rng, spent), space, EDGE, rel_tolerance=0.1, max_trials=8
    )
    return passing, failing, spent[0], edge_passed, flaky


def gate_alarm(before: list[tuple[float, bool]], now: list[tuple[float, bool]]) -> bool:
    fits = [fit_curve(AXIS, [v for v, _ in runs], [h for _, h in runs]) for runs in (before, now)]
    return regression_probability(fits[0], fits[1], R, 10.0, True, "higher") >= C


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=500)
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--truths", nargs="+", choices=list(TRUTHS), default=list(TRUTHS), help="the truths to simulate (default: all)")
    args = parser.parse_args()
    n = args.sessions
    runs_of: dict[str, list] = {}
    print(f"{n} sessions per truth; R = {R}, C = {C}, max_runs = {MAX_RUNS}, edge {EDGE:g} particles, grid step {AXIS.step:g}\n")
    print("| truth | true s80 | interval covers s80 | bound <= s80 | verdicts (passed/failed/inconclusive) | runs (mean) | seconds |")
    print("|---|---:|---:|---:|---|---:|---:|")
    with Pool(args.processes) as pool:
        for name in args.truths:
            start = time.perf_counter()
            results = pool.map(reliability_session, [(name, seed) for seed in range(n)])
            s80 = true_s(name, R)
            covered = np.mean([low <= s80 <= high for _, low, high, _, _, _ in results])
            below = np.mean([bound <= s80 for _, _, _, bound, _, _ in results])
            verdicts = "/".join(str(sum(r[0] == v for r in results)) for v in ("passed", "failed", "inconclusive"))
            runs = np.mean([r[4] for r in results])
            runs_of[name] = [r[5] for r in results]
            print(
                f"| {name} | {s80:.1f} | {covered:.3f} | {below:.3f} | {verdicts} | {runs:.1f} | {time.perf_counter() - start:.0f} |",
                flush=True,
            )

        print("\nThe votes (bisection, before the reliability search) on the same truths:\n")
        print("| truth | bracket holds s80 | bracket holds s50 | brackets of two sessions overlap | runs (mean) | edge flaky |")
        print("|---|---:|---:|---:|---:|---:|")
        for name in [t for t in list(TRUTHS)[:3] if t in args.truths]:
            votes = pool.map(vote_session, [(name, seed) for seed in range(n)])
            s80, s50 = true_s(name, R), true_s(name, 0.5)
            brackets = [(min(p, f), max(p, f)) for p, f, _, _, _ in votes if p is not None and f is not None]

            def holds(s: float, brackets: list[tuple[float, float]] = brackets) -> float:
                return float(np.mean([lo <= s <= hi for lo, hi in brackets]))

            overlap = np.mean([a[0] <= b[1] and b[0] <= a[1] for a, b in zip(brackets[::2], brackets[1::2])])
            runs = np.mean([v[2] for v in votes])
            flaky = np.mean([v[4] for v in votes])
            print(f"| {name} | {holds(s80):.3f} | {holds(s50):.3f} | {overlap:.3f} | {runs:.1f} | {flaky:.3f} |", flush=True)

        print("\nThe gate (boundary:10 %, R = 0.8, C = 0.9): each session against the one before as its baseline:\n")
        print("| baseline | this run | comparisons | regressions declared |")
        print("|---|---|---:|---:|")
        for baseline, current in (("logistic", "logistic"), ("plateau", "plateau"), ("logistic", "logistic, s80 20 % milder")):
            if baseline not in runs_of or current not in runs_of:
                continue
            pairs = [(runs_of[baseline][i], runs_of[current][i + 1]) for i in range(n - 1)]
            alarms = pool.starmap(gate_alarm, pairs)
            print(f"| {baseline} | {current} | {len(pairs)} | {np.mean(alarms):.3f} |", flush=True)


if __name__ == "__main__":
    main()
