#!/bin/bash
# N fresh sessions (empty cache) of one requirement, one after the other, each saved into one
# history under NAME (compare them with summarize.py / sal compare).
# Usage: run_sessions.sh OUT_DIR TEST N NAME [env...], e.g.
#   run_sessions.sh /tmp/sal-rel test_soiling_kitti07 5 soiling
#   SAL_FRAMES=60 run_sessions.sh /tmp/sal-rel test_night_kitti07 5 night
#   SAL_FRAMES=60 SAL_FEATURES=400 run_sessions.sh /tmp/sal-rel test_night_kitti07 5 night400
set -u
here=$(cd "$(dirname "$0")" && pwd)
out=$1; test=$2; count=$3; name=$4
python=${PYTHON:-$here/../../.venv/bin/python}
mkdir -p "$out"
cd "$here"
for i in $(seq 1 "$count"); do
  start=$(date +%s)
  "$python" -m pytest -p no:cacheprovider -k "$test" --sal-cache-dir="$out/cache_${name}_$i" --sal-history-dir="$out/history" \
    --sal-save="${name}_$i" --junitxml="$out/out_${name}_$i.xml" -q > "$out/log_${name}_$i.txt" 2>&1
  echo "name=$name session=$i rc=$? wall=$(( $(date +%s) - start ))s" >> "$out/sessions.txt"
done
