"""The boundaries of run_sessions.sh's sessions as a Markdown table, one row per session and
requirement: verdict, s80 (the severity where the requirement holds with probability 0.8) and
its 90 % interval, runs. Usage: python summarize.py OUT_DIR [NAME_PREFIX]"""

import glob
import json
import sys
import xml.etree.ElementTree as ET

print("| session | requirement | verdict | s80 | 90 % interval | runs |")
print("|---|---|---|---:|---|---:|")
for path in sorted(glob.glob(f"{sys.argv[1]}/out_{sys.argv[2] if len(sys.argv) > 2 else ''}*.xml")):
    session = path.rsplit("out_", 1)[1][:-4]
    for case in ET.parse(path).iter("testcase"):
        props = {p.get("name"): p.get("value") for p in case.iter("property")}
        if "sal_outcome" not in props:
            continue
        outcome = json.loads(props["sal_outcome"])
        b = outcome["boundary"]
        interval = "-".join(f"{v:.4g}" for v in sorted(b.get("interval") or []))
        estimate = b.get("estimate")
        print(
            f"| {session} | {case.get('name')} | {outcome['verdict']} | {'-' if estimate is None else f'{estimate:.4g}'} | {interval} | {b.get('runs')} |"
        )
