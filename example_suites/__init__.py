"""Example robustness suites to copy (see README.md). The folders are packages so that their
test file names (test_weather.py, ...) do not clash with those of a project's own tests/."""
