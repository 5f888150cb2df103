#!/usr/bin/env bash
# The project's test command: set up whatever is missing, then run every test (library and node
# tests) in one pytest run. Extra arguments go to pytest, e.g. scripts/test.sh -k separation.
set -Eeuo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
# shellcheck disable=SC1091
source scripts/env.sh
set +e
python -m pytest "$@"
rc=$?
set -e
exit $rc
