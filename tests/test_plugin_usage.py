"""Misuse of the decorators and marks, and the plugin's options, end to end (inner pytest
sessions, with and without ``-n 2``): every mistake is reported with what to write instead."""

from __future__ import annotations

import pytest
from plugin_suites import CONFTEST, HEADER, MODES, calls, has_line, run

# -- misuse is reported with what to write instead ----------------------------------------
IMPORT_ERRORS = {
    "test_not_searchable": (
        "@sal.require(tracking_rate >= 0.5, fog.heterogeneity >= 0.1)\ndef test_x(sal_outcome): pass\n",
        "*fog.heterogeneity is not searchable, so it cannot be an envelope; searchable parameters of fog: visibility_m*",
    ),
    "test_two_envelopes": (
        "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, rain.intensity_mm_h <= 10)\ndef test_x(sal_outcome): pass\n",
        (
            "*sal.require() searches one parameter; got 2 envelopes (fog.visibility_m >= 25 m, rain.intensity_mm_h <= 10 mm/h). "
            "Write one test per parameter, or chain the modules*"
        ),
    ),
    "test_metric_vs_string": (
        "@sal.require(tracking_rate >= 'high', fog.visibility_m >= 25)\ndef test_x(sal_outcome): pass\n",
        "*tracking_rate >= 'high': compare a metric with a finite number in its unit, e.g. tracking_rate >= 0.95*",
    ),
    "test_sweep_without_trial": (
        "@sal.sweep(fog.visibility_m, L=100)\n@sal.require(tracking_rate >= 0.5)\ndef test_x(sal_outcome): pass\n",
        "*test_x: sal.sweep / sal.at tests take the sal_trial fixture (def test_x(sal_trial): ...)*",
    ),
}

SESSION_ERRORS = {  # reported once every item is collected
    "sweep_without_require": (
        "@sal.sweep(fog.visibility_m, L=100)\ndef test_x(sal_trial): pass\n",
        "*test_suite.py::test_x*: sal.sweep / sal.at need a sal.require(...) below them with the criteria each level must meet*",
    ),
    "require_without_envelope": (
        "@sal.require(tracking_rate >= 0.5)\ndef test_x(sal_outcome): pass\n",
        (
            "*test_suite.py::test_x: InvalidRequirement: sal.require(tracking_rate >= 0.5) has no parameter bound to search; "
            "add one (fog.visibility_m >= 25) or put sal.sweep(...) / sal.at(...) above it*"
        ),
    ),
    "sweep_with_envelope": (
        "@sal.sweep(fog.visibility_m, L=100)\n@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_x(sal_trial): pass\n",
        "*test_suite.py::test_x*: sal.sweep / sal.at run fixed levels; drop the envelope fog.visibility_m >= 25 m from sal.require*",
    ),
}


@pytest.mark.parametrize("mode", MODES)
def test_misuse_at_import_is_a_collection_error_saying_what_to_write(pytester: pytest.Pytester, mode: list[str]) -> None:
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(**{name: HEADER + body for name, (body, _) in IMPORT_ERRORS.items()})
    result = run(pytester, mode)
    # without xdist: "Interrupted: 4 errors during collection"; with it each worker reports them
    assert result.ret == (pytest.ExitCode.TESTS_FAILED if mode else pytest.ExitCode.INTERRUPTED)
    assert result.parseoutcomes()["errors"] == len(IMPORT_ERRORS) * (2 if mode else 1)
    for name, (_, message) in IMPORT_ERRORS.items():
        result.stdout.fnmatch_lines([f"*ERROR collecting {name}.py*", message])
    assert calls(pytester) == 0


@pytest.mark.parametrize("mode", MODES)
def test_misuse_of_marks_is_a_usage_error_saying_what_to_write(pytester: pytest.Pytester, mode: list[str]) -> None:
    pytester.makeconftest(CONFTEST)
    if mode:  # xdist workers error each misused test at setup with the message
        pytester.makepyfile(**{f"test_{case}": HEADER + body for case, (body, _) in SESSION_ERRORS.items()})
        result = run(pytester, mode)
        result.assert_outcomes(errors=len(SESSION_ERRORS))
        for case, (_, message) in SESSION_ERRORS.items():
            result.stdout.fnmatch_lines([message.replace("test_suite.py", f"test_{case}.py")])
    else:  # a UsageError: the session stops before running anything
        for body, message in SESSION_ERRORS.values():
            path = pytester.makepyfile(test_suite=HEADER + body)
            result = run(pytester, mode)
            assert result.ret == pytest.ExitCode.USAGE_ERROR
            result.stderr.fnmatch_lines(["ERROR: " + message.lstrip("*")])
            path.unlink()
    assert calls(pytester) == 0


# -- options -----------------------------------------------------------------------------
@pytest.mark.parametrize("mode", MODES)
def test_help_lists_the_options_and_a_bad_check_is_a_usage_error(pytester: pytest.Pytester, mode: list[str]) -> None:
    helped = run(pytester, mode, "--help")
    assert helped.ret == 0
    helped.stdout.fnmatch_lines(
        [
            "SLAM robustness (pytest-sal):",
            "*--sal-cache-dir=DIR*cache folder*",
            "*--sal-no-cache*",
            "*--sal-history-dir=DIR*",
            "*--sal-compare-fail=CHECK*",
            "*--sal-report-md=FILE*",
            "*--sal-report-html=DIR*",
        ]
    )
    helped.stdout.fnmatch_lines(["*sal_tolerance (string):*", "*sal_max_trials (string):*", "*sal_system (string):*"])
    bad = run(pytester, mode, "--sal-compare-fail=foo")
    assert bad.ret == pytest.ExitCode.USAGE_ERROR
    bad.stderr.fnmatch_lines(["*--sal-compare-fail: 'foo': expected WHAT:LIMIT; valid forms: boundary:10% *boundary:2.5 *METRIC:0.2*"])


BAD_INI = [
    ("sal_runs", "abc", "expected a whole number >= 1 (the most runs per trial), or auto"),
    ("sal_runs", "0", "expected a whole number >= 1 (the most runs per trial), or auto"),
    ("sal_seed", "1.5", "expected a whole number >= 0 (perturbation seed)"),
    ("sal_max_trials", "-2", "expected a whole number >= 1 (trials per boundary search)"),
    ("sal_tolerance", "x", 'expected a percent > 0 of the bracket\'s larger end, such as "10%"'),
    ("sal_tolerance", "0%", 'expected a percent > 0 of the bracket\'s larger end, such as "10%"'),
    ("sal_reliability", "1", "expected a probability between 0 and 1 (the share of runs that must hold)"),
    ("sal_confidence", "0.5", "expected a probability between 0.5 and 1 (one-sided confidence)"),
    ("sal_max_runs", "0", "expected a whole number >= 1 (runs per search of a noisy system)"),
    ("sal_timeout", "-1", "expected a number > 0 (seconds per SLAM run)"),
    ("sal_cache_size", "lots", "invalid size 'lots': expected bytes with an optional unit*"),
    ("sal_kitti_segments", "10,x", "expected lengths > 0 (m) separated by commas, e.g. 10,20,30,40"),
    ("sal_kitti_segments", "0", "expected lengths > 0 (m) separated by commas, e.g. 10,20,30,40"),
    ("sal_executor", "dask", "expected local or ray"),
    ("sal_ray_address", "cluster.example", "expected auto, ray://HOST:PORT, HOST:PORT or nothing (a local Ray)"),
    ("sal_ray_address", "ray://head:port", "expected auto, ray://HOST:PORT, HOST:PORT or nothing (a local Ray)"),
]


@pytest.mark.parametrize(("name", "value", "message"), BAD_INI, ids=[f"{n}={v}" for n, v, _ in BAD_INI])
def test_a_bad_ini_value_is_a_usage_error_naming_the_option(pytester: pytest.Pytester, name: str, value: str, message: str) -> None:
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_suite=HEADER + "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_x(sal_outcome): pass\n")
    result = run(pytester, [], "-o", f"{name}={value}")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"ERROR: pytest-sal: ini option {name} = {value!r}: {message}"])
    assert calls(pytester) == 0


def test_the_ray_executor_without_ray_installed_is_one_usage_error(pytester: pytest.Pytester) -> None:
    """``--sal-executor ray`` where Ray is not installed says how to install it, before any run."""
    pytester.makeconftest(
        CONFTEST + "\nimport importlib.util\n_find = importlib.util.find_spec\n"
        "importlib.util.find_spec = lambda name, *a: None if name == 'ray' else _find(name, *a)\n"
    )
    pytester.makepyfile(test_suite=HEADER + "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_x(sal_outcome): pass\n")
    result = run(pytester, [], "--sal-executor", "ray")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["ERROR: pytest-sal: --sal-executor ray needs Ray, which is not installed: pip install 'pytest-sal[ray]'"])
    assert calls(pytester) == 0


BAD_OUTPUTS = [
    (
        "--sal-history-dir=/dev/null/x",
        "history folder (--sal-history-dir, ini sal_history_dir) /dev/null/x: /dev/null is not a folder, so /dev/null/x cannot be created; give another folder",
    ),
    (
        "--sal-cache-dir=/dev/null/x",
        "cache folder (--sal-cache-dir, ini sal_cache_dir) /dev/null/x: /dev/null is not a folder, so /dev/null/x cannot be created; give another folder",
    ),
    ("--sal-report-html=/dev/null", "--sal-report-html /dev/null: /dev/null exists and is not a folder; give another folder"),
    ("--sal-report-md={tmp}", "--sal-report-md {tmp}: {tmp} is a folder; give another file"),
    ("-o sal_system=nosuch", "ini option sal_system = 'nosuch': unknown SLAM system; known: command, orbslam3, reference_vo"),
    # a 300-character name used to pass with exit 0 and leave the baseline unsaved ("File name too long")
    ("--sal-save=" + "n" * 300, "--sal-save: the name is 300 characters long; at most 100 (it becomes part of the history's file names)"),
    ("--sal-save=", "--sal-save needs a name, e.g. --sal-save=main"),
]


@pytest.mark.parametrize(("option", "message"), BAD_OUTPUTS, ids=[o.split("=")[0] for o, _ in BAD_OUTPUTS])
def test_an_unusable_output_location_stops_the_session_before_any_run(pytester: pytest.Pytester, option: str, message: str) -> None:
    """These used to end in a traceback after every test had run (history, reports) or fail
    every test (cache folder, system)."""
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_suite=HEADER + "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_x(sal_outcome): pass\n")
    # the inner run() already passes its own --sal-cache-dir and --sal-history-dir; the last one given wins
    result = run(pytester, [], *option.replace("{tmp}", str(pytester.path)).split(" "))
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["ERROR: pytest-sal: " + message.replace("{tmp}", str(pytester.path))])
    assert calls(pytester) == 0


def test_a_missing_baseline_is_said_and_fails_only_when_asked(pytester: pytest.Pytester) -> None:
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_suite=HEADER + "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_x(sal_outcome): pass\n")
    empty = run(pytester, [], "--sal-compare")  # no history yet: nothing to compare, and it says so
    assert empty.ret == pytest.ExitCode.OK
    has_line(
        empty,
        "pytest-sal: 1 of 1 tests not compared with 'main'",
        f"no run 'main' in the history {pytester.path / 'history'}",
        "latest runs: none yet",
    )
    assert run(pytester, [], "--sal-compare", "--sal-compare-missing=fail").ret == pytest.ExitCode.TESTS_FAILED
    pytester.makeini("[pytest]\nsal_compare_missing = fail\n")
    assert run(pytester, [], "--sal-compare=nightly").ret == pytest.ExitCode.TESTS_FAILED  # the ini says fail
    assert run(pytester, [], "--sal-compare=nightly", "--sal-compare-missing=pass").ret == pytest.ExitCode.OK  # the option wins
    assert run(pytester, [], "--sal-save=main").ret == pytest.ExitCode.OK
    assert run(pytester, [], "--sal-compare").ret == pytest.ExitCode.OK  # main exists now
    pytester.makeini("[pytest]\nsal_compare_missing = maybe\n")
    result = run(pytester, [], "--sal-compare")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["ERROR: pytest-sal: ini option sal_compare_missing = 'maybe': expected pass or fail"])


@pytest.mark.parametrize("option", ["--sal-history-dir", "--sal-cache-dir", "--sal-report-md", "--sal-report-html"])
def test_a_path_option_written_with_a_space_is_refused_with_the_reason(pytester: pytest.Pytester, option: str) -> None:
    """With a space, pytest takes the path for a test path when it picks the rootdir and ini
    file (before plugins load): the ini file would be ignored and node ids would change."""
    pytester.makeconftest(CONFTEST)
    pytester.makeini("[pytest]\nsal_runs = 1\n")
    pytester.makepyfile(test_suite=HEADER + "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_x(sal_outcome): pass\n")
    target = pytester.path.parent / "elsewhere"
    target.mkdir(exist_ok=True)
    result = pytester.runpytest("-p", "no:cacheprovider", option, str(target))
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(
        [f"ERROR: pytest-sal: write {option}={target} with '=': given as two words, pytest takes {target} for a test path*"]
    )
    assert calls(pytester) == 0
    if option != "--sal-report-md":  # the same path with '=': the project's ini and test ids hold
        kept = run(pytester, [], f"{option}={target}", "-v")
        assert kept.ret == pytest.ExitCode.OK
        kept.stdout.fnmatch_lines(["configfile: tox.ini", "test_suite.py::test_x PASSED*"])
    # a name after a space is fine while no such path exists
    assert run(pytester, [], "--sal-save", "nightly").ret == pytest.ExitCode.OK


def test_more_orbslam3_workers_than_cores_is_said_at_the_start(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> None:
    # a machine with 2 cores and load average 9.3 (say, a shared CI runner): the header says so
    import sal_wrappers.pacing

    monkeypatch.setattr(sal_wrappers.pacing, "machine_load", lambda: {"loadavg": [9.3, 9.0, 8.0], "cpus": 2, "usable_cpus": 2})
    pytester.makepyfile(test_plain="def test_x():\n    pass\n")
    said = pytester.runpytest("-p", "no:cacheprovider", "--sal-no-history", "-o", "sal_system=orbslam3")
    said.stdout.fnmatch_lines(
        ["pytest-sal: 1 worker(s) x ORB-SLAM3 (about 1.5 cores each) on 2 cores with load average 9.3*re-paced and marked*"]
    )
    quiet = pytester.runpytest("-p", "no:cacheprovider", "--sal-no-history", "-o", "sal_system=reference_vo")
    assert "ORB-SLAM3" not in quiet.stdout.str()  # another system: nothing to say
    monkeypatch.setattr(sal_wrappers.pacing, "machine_load", lambda: {"loadavg": [0.2, 0.2, 0.2], "cpus": 16, "usable_cpus": 16})
    assert "worker(s)" not in pytester.runpytest("-p", "no:cacheprovider", "--sal-no-history", "-o", "sal_system=orbslam3").stdout.str()
