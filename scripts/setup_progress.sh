# What scripts/setup.sh shows while it works (sourced by it; bash). Every line a step or a tool
# writes goes to the full log ($LOG); the terminal sees each step with the time since the start
# ($T0, in $SECONDS), the tools' own progress lines, and, after $HEARTBEAT_S seconds without one,
# the last line the tool wrote: pip and colcon took 8 min on a loaded machine behind one line.
# UAM_SETUP_BRIEF=1 (run_fleet.sh's): the steps that are up to date print nothing.
HEARTBEAT_S=${HEARTBEAT_S:-20}
PENDING_STEP=""
SAID=0  # a line was shown: the brief mode's last line then says the set-up is done

elapsed() { local e=$((SECONDS - T0)); printf '%d:%02d' $((e / 60)) $((e % 60)); }

say() {  # say TEXT: one line on the terminal and in the full log, after the step it belongs to
  if [[ -n "$PENDING_STEP" ]]; then  # (already in the log)
    show "$PENDING_STEP"; PENDING_STEP=""
  fi
  SAID=1
  echo "[setup $(elapsed)] $*"
  echo "[setup $(elapsed)] $*" >>"$LOG"
}

show() { echo "[setup $(elapsed)] $*"; }  # a tool's progress: on the terminal only (its output is in the log)

step() {  # step NAME: a new step (in brief mode shown only once it has something to say)
  STEP="$1"
  if [[ "${UAM_SETUP_BRIEF:-0}" == 1 ]]; then PENDING_STEP="$1"; echo "[setup $(elapsed)] $1" >>"$LOG"
  else say "$1"; fi
}

up_to_date() {
  if [[ "${UAM_SETUP_BRIEF:-0}" == 1 ]]; then
    echo "[setup $(elapsed)]   up to date" >>"$LOG"
    PENDING_STEP=""
  else
    say "  up to date"
  fi
}

show_progress() {  # show_progress REGEX < a tool's output: the lines matching REGEX, and heartbeats
  local re=$1 line="" part="" last="" quiet=$SECONDS rc
  while :; do
    if IFS= read -r -t "$HEARTBEAT_S" line; then
      line=$part$line part=""
      [[ -n "$line" ]] && last=$line
      if [[ -n "$re" && "$line" =~ $re ]]; then show "  ${line:0:160}"; quiet=$SECONDS; fi
    else
      rc=$?
      if (( rc <= 128 )); then  # the end of the output (a last line without a newline included)
        line=$part$line
        [[ -n "$re" && -n "$line" && "$line" =~ $re ]] && show "  ${line:0:160}"
        break
      fi
      part=$part$line  # a timeout may leave a partial line: it is completed by the next read
    fi
    if (( SECONDS - quiet >= HEARTBEAT_S )); then
      show "  ... still in '$STEP' (its last output: ${last:0:140})"
      quiet=$SECONDS
    fi
  done
}

run_logged() {  # run_logged REGEX CMD...: CMD's output into the full log, its progress shown
  local re=$1; shift
  # a step that runs a tool is at work: its name is shown now (the lines below are shown from a
  # subshell, whose variables do not come back)
  if [[ -n "$PENDING_STEP" ]]; then show "$PENDING_STEP"; PENDING_STEP=""; SAID=1; fi
  "$@" 2>&1 | tee -a "$LOG" | show_progress "$re"
  local rc=${PIPESTATUS[0]}
  if (( rc != 0 )); then
    echo "[setup $(elapsed)] '$*' failed (exit code $rc); the end of its output (all of it: $LOG):"
    tail -n 20 "$LOG" | sed 's/^/    /'
  fi
  return "$rc"
}
