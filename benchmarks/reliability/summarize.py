"""One line per session of run_sessions.sh: verdict, s_R/C, s_R, its interval, s50, runs, and
the runs that held per value. Usage: python summarize.py OUT_DIR [NAME]"""

import glob
import json
import sys
import xml.etree.ElementTree as ET

pattern = f"{sys.argv[1]}/out_{sys.argv[2] if len(sys.argv) > 2 else ''}*.xml"
for path in sorted(glob.glob(pattern)):
    props = {p.get("name"): p.get("value") for p in ET.parse(path).iter("property")}
    if "sal_outcome" not in props:
        continue
    o = json.loads(props["sal_outcome"])
    b = o["boundary"]
    print(
        path.rsplit("out_", 1)[1][:-4],
        o["verdict"],
        f"bound {b.get('bound', b.get('pass_value')):.4g}",
        f"estimate {b.get('estimate') or 0:.4g}",
        "interval " + "-".join(f"{v:.4g}" for v in sorted(b.get("interval") or [])),
        f"s50 {b.get('s50') or 0:.4g}",
        f"p(edge)>=R sure {b.get('holds_at_edge')}",
        f"{b.get('runs')} runs",
        sep=" | ",
    )
    held = {t["value"]: f"{sum(r['passed'] for r in t['runs'])}/{len(t['runs'])}" for t in sorted(o["trials"], key=lambda t: t["value"])}
    print("   ", ", ".join(f"{v:g}: {h}" for v, h in held.items()))
