#!/usr/bin/env bash
# The Python 3.13 environment of InterUSS's own test code (requirements-interuss.txt:
# interuss-monitoring and what it pulls in, pinned), cached outside the repository, keyed by the
# requirements file's hash, so every checkout and worktree of the same pins shares one:
#   ${XDG_CACHE_HOME:-$HOME/.cache}/uam/interuss-<first 16 hex digits of its SHA-256>
#
# Sourced by scripts/setup.sh (function setup_interuss_env, with setup_progress.sh's step /
# up_to_date / run_logged / say). Run directly, it prints the environment's folder
# (`bash scripts/interuss_env.sh dir`) or the reason it is missing (`... why`), which the tests
# that use it read to find it or to say why they are skipped.
#
# Made only when missing; its stamp (.uam-interuss-ok) is written once its packages import, so a
# half-made environment is never taken for a made one (it is made again). No Python 3.13, or a registry that does not
# answer: the step says so, writes the reason next to where the environment would be
# (interuss-<hash>.unavailable) and the set-up goes on; those tests are then skipped with it.
#
# Environment: UAM_PYTHON313=/path/to/python3.13 (default: python3.13 on PATH, else pyenv's 3.13);
# UAM_INTERUSS=0 skips the step.

_interuss_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
INTERUSS_REQ="$_interuss_root/requirements-interuss.txt"
# what the tests use: the environment is made only if these import
INTERUSS_IMPORTS="import monitoring.monitorlib.clients.flight_planning.client_v1, \
monitoring.monitorlib.clients.versioning.client_interuss, monitoring.monitorlib.schema_validation"

interuss_env_dir() {  # the environment's folder for the current requirements file
  local h
  h=$(sha256sum "$INTERUSS_REQ" | cut -c1-16)
  echo "${XDG_CACHE_HOME:-$HOME/.cache}/uam/interuss-$h"
}

find_python313() {  # prints a Python 3.13 interpreter that runs, or nothing
  local c
  local candidates=("${UAM_PYTHON313:-}" python3.13 "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.13*/bin/python)
  for c in "${candidates[@]}"; do
    [[ -n "$c" ]] || continue
    # (a pyenv shim exists on PATH even when it cannot run 3.13: run it to know)
    if "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 13))' >/dev/null 2>&1; then
      command -v "$c"
      return 0
    fi
  done
}

setup_interuss_env() {  # the step: make the environment if it is missing; never fails the set-up
  local dir py why
  dir=$(interuss_env_dir)
  step "InterUSS test environment (Python 3.13, requirements-interuss.txt)"
  if [[ "${UAM_INTERUSS:-1}" == 0 ]]; then
    say "  skipped (UAM_INTERUSS=0): the tests that run InterUSS's code will be skipped"
    return 0
  fi
  if [[ -f "$dir/.uam-interuss-ok" ]]; then
    up_to_date
    return 0
  fi
  mkdir -p "$(dirname "$dir")"
  py=$(find_python313)
  if [[ -z "$py" ]]; then
    why="no Python 3.13 found (tried \$UAM_PYTHON313, python3.13, ${PYENV_ROOT:-$HOME/.pyenv}/versions/3.13*): interuss-monitoring needs it"
    echo "$why" > "$dir.unavailable"
    say "  skipped: $why; the tests that run InterUSS's code will be skipped"
    return 0
  fi
  say "  creating $dir with $py"
  rm -rf "$dir"  # a folder without the stamp is a half-made one
  if "$py" -m venv "$dir" >>"$LOG" 2>&1 \
    && run_logged '^(Collecting|Installing collected packages|Successfully installed|ERROR)' \
         "$dir/bin/python" -m pip install --disable-pip-version-check --progress-bar off --retries 2 \
         -r "$INTERUSS_REQ" \
    && "$dir/bin/python" -c "$INTERUSS_IMPORTS" >>"$LOG" 2>&1
  then
    touch "$dir/.uam-interuss-ok"
    rm -f "$dir.unavailable"
    return 0
  fi
  rm -rf "$dir"
  why="pip could not install requirements-interuss.txt with $py (is PyPI reachable? see log/setup.log)"
  echo "$why" > "$dir.unavailable"
  say "  skipped: $why; the tests that run InterUSS's code will be skipped"
  return 0
}

if [[ "${BASH_SOURCE[0]}" == "$0" ]]; then
  case "${1:-dir}" in
    dir) interuss_env_dir ;;
    why) d=$(interuss_env_dir); if [[ -f "$d/.uam-interuss-ok" ]]; then echo "ready: $d"; else
           cat "$d.unavailable" 2>/dev/null || echo "no InterUSS environment at $d: scripts/setup.sh makes it"; fi ;;
    *) echo "usage: bash scripts/interuss_env.sh [dir|why]" >&2; exit 2 ;;
  esac
fi
