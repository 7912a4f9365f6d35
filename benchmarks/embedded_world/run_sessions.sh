#!/bin/bash
# One fresh session (empty cache) of the five requirements on one world, saved into one history.
# Usage: SAL_WORLD=kitti|urban run_sessions.sh OUT_DIR NAME [N]  (N sessions, default 1; -k with K=...)
set -u
here=$(cd "$(dirname "$0")" && pwd)
out=$1; name=$2; count=${3:-1}
python=${PYTHON:-$here/../../.venv/bin/python}
mkdir -p "$out"
cd "$here"
for i in $(seq 1 "$count"); do
  start=$(date +%s)
  "$python" -m pytest -p no:cacheprovider ${K:+-k "$K"} --sal-cache-dir="$out/cache_${name}_$i" --sal-history-dir="$out/history" \
    --sal-save="${name}_$i" --junitxml="$out/out_${name}_$i.xml" -q > "$out/log_${name}_$i.txt" 2>&1
  echo "name=$name world=${SAL_WORLD:-urban} session=$i rc=$? wall=$(( $(date +%s) - start ))s" >> "$out/sessions.txt"
done
