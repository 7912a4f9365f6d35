#!/usr/bin/env bash
# sal-gate.sh: the pytest-sal regression gate, one script for every CI system.
#
# usage: example_suites/ci/sal-gate.sh main|pr [PYTEST_ARGS...]
#
#   main  run the suite and save the run as the baseline $SAL_BASELINE in the history, then
#         prune the history to the newest $SAL_KEEP runs (each name's newest run stays)
#   pr    run the suite and fail every test whose boundary regressed against the baseline
#         $SAL_BASELINE by more than $SAL_FAIL; a run that fails the gate is saved without a
#         name, so rerunning it fails again
#
# Arguments after the mode go to pytest as they are (e.g. -k fog).
#
# environment (default):
#   SAL_SUITE            test paths, separated by spaces (example_suites)
#   SAL_HISTORY          run history, where the baseline is kept (.sal/history)
#   SAL_CACHE            trial cache (.sal/cache)
#   SAL_OUT              reports: summary.md, report/index.html, junit.xml (sal-out)
#   SAL_BASELINE         the baseline's run name (main)
#   SAL_FAIL             regression checks, separated by spaces (boundary:10%)
#   SAL_COMPARE_MISSING  a test with no baseline: pass (said under the table) or fail (pass)
#   SAL_WORKERS          pytest-xdist workers (auto)
#   SAL_KEEP             runs the history keeps after 'main' (50)
#   PYTHON               the interpreter that has pytest-sal installed (python)
#   GITHUB_STEP_SUMMARY  set by GitHub Actions: the Markdown summary is appended to it. GitLab
#                        has no job summary: keep $SAL_OUT/summary.md as an artifact and print it.
#
# exit status: pytest's (0 every test passed, 1 a test failed or regressed, 2-4 an error);
# 5 (no test collected) is an error too: a gate that ran nothing must not pass; 64 a bad mode.
set -euo pipefail

usage() {
    sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"
}

mode=${1:-}
case "$mode" in
    main | pr) shift ;;
    -h | --help) usage; exit 0 ;;
    *) usage >&2; echo "sal-gate: give the mode main or pr, not '${mode}'" >&2; exit 64 ;;
esac

SAL_SUITE=${SAL_SUITE:-example_suites}
SAL_HISTORY=${SAL_HISTORY:-.sal/history}
SAL_CACHE=${SAL_CACHE:-.sal/cache}
SAL_OUT=${SAL_OUT:-sal-out}
SAL_BASELINE=${SAL_BASELINE:-main}
SAL_FAIL=${SAL_FAIL:-boundary:10%}
SAL_COMPARE_MISSING=${SAL_COMPARE_MISSING:-pass}
SAL_WORKERS=${SAL_WORKERS:-auto}
SAL_KEEP=${SAL_KEEP:-50}
PYTHON=${PYTHON:-python}

read -r -a suite <<< "$SAL_SUITE"
read -r -a checks <<< "$SAL_FAIL"
summary="$SAL_OUT/summary.md"
mkdir -p "$SAL_OUT"
rm -f "$summary"  # a summary left by an earlier run must not stand for this one

# Path options are written with '=': given as two words, pytest would take the path for a
# test path when it picks the rootdir and ini file.
args=(-n "$SAL_WORKERS" "${suite[@]}"
      "--sal-history-dir=$SAL_HISTORY" "--sal-cache-dir=$SAL_CACHE"
      "--sal-report-md=$summary" "--sal-report-html=$SAL_OUT/report" "--junitxml=$SAL_OUT/junit.xml")
if [[ $mode == main ]]; then
    args+=("--sal-save=$SAL_BASELINE")
else
    args+=("--sal-compare=$SAL_BASELINE" "--sal-compare-missing=$SAL_COMPARE_MISSING")
    for check in "${checks[@]}"; do
        args+=("--sal-compare-fail=$check")
    done
fi

status=0
"$PYTHON" -m pytest "${args[@]}" "$@" || status=$?

problem=""
if ((status == 5)); then
    problem="sal-gate: no test ran in '$SAL_SUITE' (pytest exit 5): a gate that ran nothing does not pass"
elif [[ ! -f $summary ]]; then
    problem="sal-gate: pytest exited $status without writing $summary; see the job log"
fi
if [[ -n $problem ]]; then
    echo "$problem" >&2
fi
if [[ -n ${GITHUB_STEP_SUMMARY:-} ]]; then
    if [[ -f $summary ]]; then
        cat "$summary" >> "$GITHUB_STEP_SUMMARY"
    fi
    if [[ -n $problem ]]; then
        printf '\n**%s**\n' "$problem" >> "$GITHUB_STEP_SUMMARY"
    fi
fi

if [[ $mode == main && -d $SAL_HISTORY ]]; then
    "$PYTHON" -m pytest_sal.cli.main history prune --keep "$SAL_KEEP" --history-dir "$SAL_HISTORY"
elif [[ $mode == pr ]] && ((status == 1)); then
    echo "sal-gate: a test failed or regressed against '$SAL_BASELINE'. A deliberate change is accepted by merging it: the main run saves the new baseline." >&2
fi
exit "$status"
