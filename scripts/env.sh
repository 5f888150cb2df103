# Source this file (bash) to use the built workspace: `source scripts/env.sh`.
# It puts the project venv first on PATH, makes ROS 2 Jazzy visible (from /opt/ros/jazzy or from
# the PyPI wheels in .venv, as scripts/setup.sh chose) and sources install/setup.bash.
_uam_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ ! -f "$_uam_root/install/setup.bash" ]]; then
  echo "scripts/env.sh: the workspace is not built; run scripts/setup.sh first" >&2
  return 1 2>/dev/null || exit 1
fi
if [[ "$(cat "$_uam_root/.venv/.uam-mode" 2>/dev/null)" == system-* ]]; then
  set +u; source /opt/ros/jazzy/setup.bash
else
  export VIRTUAL_ENV="$_uam_root/.venv"
  case ":${AMENT_PREFIX_PATH:-}:" in *":$VIRTUAL_ENV:"*) ;; *) export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}";; esac
  set +u
fi
export PATH="$_uam_root/.venv/bin:$PATH"
source "$_uam_root/install/setup.bash"
# Keep discovery on this machine unless the caller chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
unset _uam_root
