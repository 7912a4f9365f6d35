"""The sessions of one requirement against each other and against all their runs pooled:
whether their s_R intervals overlap pairwise, whether the curve fitted on every run of every
session lies inside each session's band at the pooled s_R, and the gate between each pair
(every session as the baseline of every other: boundary:10 %); with BASELINE, also each
session of NAME against each of BASELINE (a changed system: detections).
Usage: python pooled.py OUT_DIR NAME [BASELINE]"""

import glob
import itertools
import json
import sys
import xml.etree.ElementTree as ET

from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.engine.search.reliability_compare import refit, regression_probability
from pytest_sal.engine.search.reliability_curve import fit_curve


def sessions(name: str) -> dict[str, Outcome]:
    found = {}
    for path in sorted(glob.glob(f"{sys.argv[1]}/out_{name}_*.xml")):
        props = {p.get("name"): p.get("value") for p in ET.parse(path).iter("property")}
        if "sal_outcome" in props:
            found[path.rsplit("out_", 1)[1][:-4]] = Outcome.from_dict(json.loads(props["sal_outcome"]))
    return found


outcomes = sessions(sys.argv[2])
fits = {name: refit(o) for name, o in outcomes.items()}
first = next(iter(outcomes.values()))
b = first.boundary
r, c = b.reliability, b.confidence
axis = next(iter(fits.values())).axis
runs = [(t.value, bool(x.get("passed"))) for o in outcomes.values() for t in o.trials for x in t.runs if not x.get("abstained")]
pooled = fit_curve(axis, [v for v, _ in runs], [h for _, h in runs])
s_pooled = pooled.s_r(r, c)
x_star = s_pooled.estimate
p_star = pooled.p_at(x_star, c).estimate
unit = b.unit
print(
    f"{len(outcomes)} sessions, {len(runs)} runs pooled: s{100 * r:.0f} = {float(axis.to_value(x_star)):.4g} {unit}, "
    f"90 % interval {float(axis.to_value(s_pooled.low)):.4g}-{float(axis.to_value(s_pooled.high)):.4g}, p there {p_star:.3f}"
)
for name, fit in fits.items():
    band = fit.p_at(x_star, c)
    o = outcomes[name]
    inside = band.low <= p_star <= band.high
    print(
        f"  {name}: {o.verdict}, {o.boundary.text()}; band at the pooled s{100 * r:.0f}: {band.low:.3f}-{band.high:.3f} "
        f"({'contains' if inside else 'MISSES'} the pooled curve's {p_star:.3f}); {o.boundary.runs} runs"
    )
pairs = list(itertools.combinations(outcomes, 2))
overlap = [
    (a, b_)
    for a, b_ in pairs
    if min(outcomes[a].boundary.interval) <= max(outcomes[b_].boundary.interval)
    and min(outcomes[b_].boundary.interval) <= max(outcomes[a].boundary.interval)
]
print(f"s_R intervals overlapping: {len(overlap)} of {len(pairs)} pairs")
alarms = []
for base, now in itertools.permutations(outcomes, 2):
    probability = regression_probability(fits[base], fits[now], r, 10.0, True, first.worse)
    alarms.append((base, now, probability))
declared = [a for a in alarms if a[2] >= c]
print(
    f"gate boundary:10 % between unchanged sessions: {len(declared)} of {len(alarms)} comparisons declare a regression; "
    f"largest probability {max((a[2] for a in alarms), default=0.0):.3f}"
)
if len(sys.argv) > 3:
    baselines = sessions(sys.argv[3])
    caught = []
    for o in baselines.values():
        for fit in fits.values():
            caught.append(regression_probability(refit(o), fit, r, 10.0, True, first.worse) >= c)
    print(f"against {sys.argv[3]} as the baseline: {sum(caught)} of {len(caught)} comparisons declare a regression")
