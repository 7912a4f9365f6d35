"""One line per session of run_sessions.sh: verdict, interval, trials, runs, confidence, and the
tracking rate of every run per trial. Usage: python summarize.py OUT_DIR"""

import glob
import json
import sys
import xml.etree.ElementTree as ET

for path in sorted(glob.glob(f"{sys.argv[1]}/out_*.xml")):
    props = {p.get("name"): p.get("value") for p in ET.parse(path).iter("property")}
    o = json.loads(props["sal_outcome"])
    b = o["boundary"]
    runs = sum(len(t["runs"]) for t in o["trials"])
    print(
        path.rsplit("out_", 1)[1][:-4],
        o["verdict"],
        f"{b['fail_value']:.4g}-{b['pass_value']:.4g} {b['unit']}",
        f"{len(o['trials'])} trials",
        f"{runs} runs",
        o["confidence"],
        sep=" | ",
    )
    print(
        "   ",
        [
            (round(t["value"], 3), "pass" if t["passed"] else "fail", [round(r["tracking_rate"] or 0, 2) for r in t["runs"]])
            for t in o["trials"]
        ],
    )
