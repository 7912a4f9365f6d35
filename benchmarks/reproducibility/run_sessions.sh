#!/bin/bash
# Five fresh sessions (empty caches, no history) with votes (sal_runs auto), then five with one
# run per trial (sal_runs=1), one after the other. Usage: run_sessions.sh OUT_DIR
# Then: python summarize.py OUT_DIR
set -u
here=$(cd "$(dirname "$0")" && pwd)
out=${1:-/tmp/sal-repro}
python=${PYTHON:-$here/../../.venv/bin/python}
mkdir -p "$out"
cd "$here"
for mode in auto 1; do
  for i in 1 2 3 4 5; do
    start=$(date +%s)
    "$python" -m pytest -p no:cacheprovider -o sal_runs=$mode --sal-cache-dir="$out/cache_${mode}_$i" --sal-no-history \
      --junitxml="$out/out_${mode}_$i.xml" -q > "$out/log_${mode}_$i.txt" 2>&1
    echo "mode=$mode session=$i rc=$? wall=$(( $(date +%s) - start ))s" >> "$out/sessions.txt"
  done
done
