"""Per test of suites_before_after.sh: verdict, pass and fail value, trials and runs, before and
after; exit 1 when any differs. Usage: python suites_compare.py OUT_DIR"""

import json
import sys
import xml.etree.ElementTree as ET


def outcomes(path: str) -> dict[str, tuple]:
    found = {}
    for case in ET.parse(path).iter("testcase"):
        props = {p.get("name"): p.get("value") for p in case.iter("property")}
        o = json.loads(props["sal_outcome"]) if "sal_outcome" in props else {}
        b = o.get("boundary") or {}
        trials = o.get("trials", [])
        found[case.get("name")] = (
            o.get("verdict"),
            b.get("pass_value"),
            b.get("fail_value"),
            len(trials),
            sum(len(t.get("runs", [])) for t in trials),
        )
    return found


before, after = (outcomes(f"{sys.argv[1]}/{label}/junit.xml") for label in ("before", "after"))
print("| test | verdict | pass value | fail value | trials | runs | same |\n|---|---|---:|---:|---:|---:|---|")
differ = 0
for name, row in before.items():
    same = after.get(name) == row
    differ += not same
    print(f"| {name} | {row[0]} | {row[1]} | {row[2]} | {row[3]} | {row[4]} | {'yes' if same else f'NO: {after.get(name)}'} |")
print(f"\n{len(before) - differ} of {len(before)} tests identical")
sys.exit(1 if differ else 0)
