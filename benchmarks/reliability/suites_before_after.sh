#!/bin/bash
# The example suites with reference_vo (deterministic) on two engines, the same suite files:
# the suites of BEFORE (a commit) run once with BEFORE's engine and once with this checkout's.
# Usage: suites_before_after.sh BEFORE OUT_DIR, e.g. suites_before_after.sh b04c2d3 /tmp/det
# then: python suites_compare.py OUT_DIR
set -u
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
before=$1; out=$2
python=${PYTHON:-$repo/.venv/bin/python}
mkdir -p "$out"
tree="$out/tree_$before"
[ -d "$tree" ] || git -C "$repo" worktree add -f "$tree" "$before" > /dev/null
for label in before after; do
  engine=$tree; [ "$label" = after ] && engine=$repo
  rm -rf "${out:?}/$label"; mkdir -p "$out/$label"
  start=$(date +%s)
  (cd "$tree" && PYTHONPATH=$engine "$python" -m pytest example_suites -o sal_system=reference_vo -p no:cacheprovider \
    --sal-cache-dir="$out/$label/cache" --sal-history-dir="$out/$label/hist" --junitxml="$out/$label/junit.xml" -q > "$out/$label/log.txt" 2>&1)
  echo "label=$label rc=$? wall=$(( $(date +%s) - start ))s" >> "$out/walls.txt"
done
