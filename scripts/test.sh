#!/usr/bin/env bash
# The project's test command: set up whatever is missing, lint (ruff), then run every test (library
# and node tests) in one pytest run. Extra arguments go to pytest, e.g. scripts/test.sh -k separation.
# The tests run in UAM_TEST_WORKERS pytest-xdist worker processes (default 2, one per core of the
# reference machine; 0 = in this process), each test file on one worker (--dist loadfile: a file's
# module fixtures, e.g. a solve service's worker pool, are built once). Each worker claims its own
# ROS domain id (conftest.py's lock files), so the node tests of two workers never hear each other.
set -Eeuo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
# shellcheck disable=SC1091
source scripts/env.sh
WORKERS=(); n="${UAM_TEST_WORKERS:-2}"
# a worker that crashes (conftest.py's hang watchdog aborts one stuck in native code) is replaced
# twice at most: xdist gives its test file again to the next worker, so a test that hangs every
# time would otherwise cost UAM_TEST_HANG_S nine times over
if [[ "$n" != 0 ]] && python -c "import xdist" 2>/dev/null; then WORKERS=(-n "$n" --dist loadfile --max-worker-restart 2); fi
# lint first (ruff.toml: unused and undefined names, syntax, complexity over 25), well under a
# second: a finding fails the run as a failing test would
if ! python -m ruff check --quiet src test; then
  echo "scripts/test.sh: ruff found the problems above (ruff.toml); fix them or say why in a noqa comment" >&2
  exit 1
fi
# a loaded machine: UAM_TEST_LOAD_FACTOR (default 1) scales the per-test limit (pytest.ini: 180 s),
# the hang watchdog (240 s) and the few wall-time bounds of the tests (test/load_factor.py)
LOAD_FACTOR="${UAM_TEST_LOAD_FACTOR:-1}"
TIMEOUT_S=$(python -c "import sys; f = float(sys.argv[1]); assert f >= 1; print(int(180 * f))" "$LOAD_FACTOR") \
  || { echo "scripts/test.sh: UAM_TEST_LOAD_FACTOR: '$LOAD_FACTOR' must be a number >= 1" >&2; exit 2; }
export UAM_TEST_HANG_S="${UAM_TEST_HANG_S:-$(( TIMEOUT_S * 4 / 3 ))}"
set +e
# the 30 slowest tests are listed after the summary: where `make test`'s time goes
python -m pytest --timeout="$TIMEOUT_S" --durations=30 "${WORKERS[@]}" "$@"
rc=$?
set -e
exit $rc
