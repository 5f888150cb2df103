#!/usr/bin/env bash
# Run the UAM node graph end to end: solver, planner, request generator, recorder and simulator,
# each started with `ros2 run` (or, where the ros2 command line is absent, as with the PyPI
# wheels, the same installed executable install/<pkg>/lib/<pkg>/<exe>). The run is recorded to
# MCAP (and a Rerun .rrd); at the end the analysis summary and safety audit are printed.
#
# usage: scripts/run_fleet.sh [options]
#   --backend NAME     MWIS backend of the solver (default exact; `--backend list` lists them)
#   --policy P         mwis | fifo | firstfit (default mwis)
#   --objective O      what the MWIS maximises: a registered objective, paper | count | delay |
#                      priority | fair, ... (default paper; python -m uam_planner.objectives; docs/objectives.md)
#   --baseline-order B arrival | priority: the order of fifo and firstfit (default arrival)
#   --priority-share P share of random requests of priority class 1, e.g. 0.05 (default 0)
#   --priority-grants FILE  the priority classes each operator may ask for (uam_planner.grants;
#                      default: the generator's class, 0 for any other operator); above it: refused
#   --horizon H        epochs the MWIS plans jointly (rolling horizon, default 1: the paper's)
#   --commit-ahead B   true | false: with --horizon > 1, commit the horizon's later departures now
#                      as reservations, never re-optimised (default false)
#   --replan-policy R  mwis | firstfit: how the flights a constraint update affects are re-planned
#                      (default: the policy's own; docs/replanning.md)
#   --lead-time S      requests are filed S seconds before their earliest departure (default 0)
#   --reaction B       true | false: the planner updates a nonconforming flight's intent (issue 23;
#                      reports from the conformance monitor, checked by the planner; default false)
#   --reaction-period S with --reaction true, the planner also reacts every S seconds between
#                      epochs (a multiple of the simulator's step, less than the epoch; default 0:
#                      at epochs only; docs/disturbances.md)
#   --probe S          with --reaction true, the conflict probe's look-ahead [s]: at each reaction
#                      the airborne flights are projected at their observed progress and pairs
#                      predicted to lose separation within S s are re-planned (default 0: off;
#                      docs/disturbances.md, 5)
#   --probe-margin M   with --probe, the probe's margin [m]: it predicts losses of the minimum + M
#                      and deconflicts its own updates with at least that (default 0)
#   --rate R           requests per 30 s (default 10, the paper's middle rate)
#   --duration S       simulated seconds (default 3500)
#   --seed N           seed of the demand and of stochastic solvers (default 0)
#   --network FILE     routing network (default config/networks/singapore.yaml; e.g.
#                      config/networks/singapore-layered.yaml: vertiports with pads, 4 flight levels)
#   --separation M     sphere | cylinder: loss of separation as the paper's 3D minimum or horizontal
#                      < H while vertical < V (default: the network's own, cylinder for a layered
#                      network, else sphere; a contradicting choice is warned of)
#   --separation-m H   separation minimum, the cylinder's horizontal H [m] (default 100)
#   --vertical-separation-m V   the cylinder's vertical minimum [m] (default 30)
#   --slot-s S         departure slots of S seconds inside the epoch (default 0: the paper's rule,
#                      depart at the epoch time)
#   --climb-rate R, --descent-rate R   vertical rates at vertiports of a layered network [m/s] (5, 3)
#   --demand FILE      replay a demand file instead of random requests
#   --constraints FILE airspace constraints the planner plans around (GeoJSON or ED-269 zones,
#                      docs/constraints.md; e.g. config/constraints_example.geojson)
#   --spatial-buffer-m B, --temporal-buffer-s T   planning buffers on the separation [m], [s]
#                      (default 0, 0; docs/disturbances.md; the audits keep the true minimum)
#   --wind W, --wind-from D   steady wind [m/s] blowing from D [deg from north] (default 0, 270)
#   --gust G           gusts: standard deviation per horizontal component [m/s] (default 0)
#   --speed-error E    per-flight airspeed error, uniform in [-E, E] (default 0; 0.1 = +-10 %)
#   --delay-mean S     mean departure delay [s], exponential (default 0); all disturbances 0 =
#                      plans flown exactly (docs/disturbances.md)
#   --vertical-gust G  vertical gusts: standard deviation [m/s] (default 0)
#   --altitude-error M per-flight altitude-hold error, uniform in [-M, M] [m] (default 0)
#   --mode M           lockstep | realtime (default lockstep)
#   --rtf X            real-time factor in realtime mode (default 1)
#   --rerun M          off | save | spawn | connect (default save: a .rrd next to the MCAP)
#   --foxglove-port N  serve a live Foxglove WebSocket view on port N (default 0 = off; docs/views.md)
#   --uss-port N       serve the plans and constraints as ASTM F3548 operational intents over HTTP on
#                      127.0.0.1:N (the USS-USS interface; default 0 = off; docs/f3548.md)
#   --volume-piece S   with --uss-port: the longest time window of one published Volume4D [s] (default 5);
#                      the planner then keeps the published volumes of every two flights disjoint too
#                      (F3548 mode; docs/f3548.md)
#   --dss-url U        with --uss-port: the DSS whose operational intent references the USS keeps in step
#                      with its intents (default '' = none; docs/f3548.md, DSS reference management)
#   --dss-token-file F with --dss-url: a file holding the bearer token sent to the DSS
#   --dss-auth-url U   with --dss-url: an auth server's token endpoint asked for each token (InterUSS's
#                      dummy OAuth), instead of --dss-token-file
#   --uss-auth A       verify | off: the USS server's access tokens (default verify: every request needs a
#                      bearer token signed by the auth server's key, unexpired, for this USS, with the
#                      endpoint's F3548 scope; off: none asked for, announced on the console and recorded)
#   --uss-auth-key F   the auth server's public key for --uss-auth verify (PEM or JWKS; default: a
#                      development key pair made in <out>/uss-auth, with a token for local clients in
#                      <out>/uss-auth/token)
#   --uss-audience A   audiences a token may name, comma-separated (default: localhost and 127.0.0.1)
#   --conformance C    start the conformance monitor: true, false, or auto (default) = only when a
#                      disturbance is set (it runs at the recorder's nice value)
#   --recorder-nice N  the recorder's nice value (default 19): it is not in the lockstep loop, so the
#                      loop's nodes get the CPU first and the recorder drains its queue after
#                      (its reader history holds the whole backlog, the simulator waits for its
#                      acknowledgements before it exits, and it checks what it received)
#   --out DIR          output folder (default a new folder $UAM_RUNS_DIR/<date>-<policy>-<backend>-r<rate>-s<seed>-XXXX,
#                      UAM_RUNS_DIR defaulting to runs/; unique even for runs started in the same second)
# Ctrl-C, SIGTERM and SIGHUP stop every node cleanly; the recording is closed properly. If this
# script is killed outright (SIGKILL), every node gets SIGTERM from the kernel (each is started
# under `setpriv --pdeathsig TERM`) and still closes its files.
set -Eeuo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

BACKEND=exact POLICY=mwis RATE=10 DURATION=3500 SEED=0 NETWORK=config/networks/singapore.yaml
SPATIAL_BUFFER=0 TEMPORAL_BUFFER=0 WIND=0 WIND_FROM=270 GUST=0 SPEED_ERROR=0 DELAY_MEAN=0 VERTICAL_GUST=0 ALTITUDE_ERROR=0
DEMAND="" CONSTRAINTS="" MODE=lockstep RTF=1 RERUN=save OUT="" FOXGLOVE_PORT=0 USS_PORT=0 RECORDER_NICE=19 RECORDER_STOP_S=60
USS_AUTH=verify USS_AUTH_KEY="" USS_AUDIENCE="" VOLUME_PIECE=5 DSS_URL="" DSS_TOKEN_FILE="" DSS_AUTH_URL=""
CONFORMANCE=auto
SEPARATION="" SEPARATION_M=100 VERTICAL_M=30 SLOT_S=0 CLIMB=5 DESCENT=3
PRIORITY_GRANTS="" OBJECTIVE=paper BASELINE_ORDER=arrival PRIORITY_SHARE=0 HORIZON=1 LEAD_TIME=0 COMMIT_AHEAD=false REACTION=false REACTION_PERIOD=0 PROBE=0 PROBE_MARGIN=0 REPLAN_POLICY=""
die() { echo "run_fleet: $*" >&2; exit 2; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --backend) BACKEND="${2:?--backend needs a value}"; shift 2;;
    --policy) POLICY="${2:?--policy needs a value}"; shift 2;;
    --objective) OBJECTIVE="${2:?--objective needs a value}"; shift 2;;
    --baseline-order) BASELINE_ORDER="${2:?--baseline-order needs a value}"; shift 2;;
    --priority-share) PRIORITY_SHARE="${2:?--priority-share needs a value}"; shift 2;;
    --priority-grants) PRIORITY_GRANTS="${2:?--priority-grants needs a value}"; shift 2;;
    --horizon) HORIZON="${2:?--horizon needs a value}"; shift 2;;
    --commit-ahead) COMMIT_AHEAD="${2:?--commit-ahead needs a value}"; shift 2;;
    --reaction) REACTION="${2:?--reaction needs a value}"; shift 2;;
    --reaction-period) REACTION_PERIOD="${2:?--reaction-period needs a value}"; shift 2;;
    --probe) PROBE="${2:?--probe needs a value}"; shift 2;;
    --probe-margin) PROBE_MARGIN="${2:?--probe-margin needs a value}"; shift 2;;
    --replan-policy) REPLAN_POLICY="${2?--replan-policy needs a value}"; shift 2;;
    --lead-time) LEAD_TIME="${2:?--lead-time needs a value}"; shift 2;;
    --rate) RATE="${2:?--rate needs a value}"; shift 2;;
    --duration) DURATION="${2:?--duration needs a value}"; shift 2;;
    --seed) SEED="${2:?--seed needs a value}"; shift 2;;
    --network) NETWORK="${2:?--network needs a value}"; shift 2;;
    --demand) DEMAND="${2:?--demand needs a value}"; shift 2;;
    --constraints) CONSTRAINTS="${2:?--constraints needs a value}"; shift 2;;
    --spatial-buffer-m) SPATIAL_BUFFER="${2:?--spatial-buffer-m needs a value}"; shift 2;;
    --temporal-buffer-s) TEMPORAL_BUFFER="${2:?--temporal-buffer-s needs a value}"; shift 2;;
    --wind) WIND="${2:?--wind needs a value}"; shift 2;;
    --wind-from) WIND_FROM="${2:?--wind-from needs a value}"; shift 2;;
    --gust) GUST="${2:?--gust needs a value}"; shift 2;;
    --speed-error) SPEED_ERROR="${2:?--speed-error needs a value}"; shift 2;;
    --delay-mean) DELAY_MEAN="${2:?--delay-mean needs a value}"; shift 2;;
    --vertical-gust) VERTICAL_GUST="${2:?--vertical-gust needs a value}"; shift 2;;
    --altitude-error) ALTITUDE_ERROR="${2:?--altitude-error needs a value}"; shift 2;;
    --mode) MODE="${2:?--mode needs a value}"; shift 2;;
    --rtf) RTF="${2:?--rtf needs a value}"; shift 2;;
    --rerun) RERUN="${2:?--rerun needs a value}"; shift 2;;
    --foxglove-port) FOXGLOVE_PORT="${2:?--foxglove-port needs a value}"; shift 2;;
    --uss-port) USS_PORT="${2:?--uss-port needs a value}"; shift 2;;
    --dss-url) DSS_URL="${2:?--dss-url needs a value}"; shift 2;;
    --dss-token-file) DSS_TOKEN_FILE="${2:?--dss-token-file needs a value}"; shift 2;;
    --dss-auth-url) DSS_AUTH_URL="${2:?--dss-auth-url needs a value}"; shift 2;;
    --volume-piece) VOLUME_PIECE="${2:?--volume-piece needs a value}"; shift 2;;
    --uss-auth) USS_AUTH="${2:?--uss-auth needs a value}"; shift 2;;
    --uss-auth-key) USS_AUTH_KEY="${2:?--uss-auth-key needs a value}"; shift 2;;
    --uss-audience) USS_AUDIENCE="${2:?--uss-audience needs a value}"; shift 2;;
    --conformance) CONFORMANCE="${2:?--conformance needs a value}"; shift 2;;
    --recorder-nice) RECORDER_NICE="${2:?--recorder-nice needs a value}"; shift 2;;
    --out) OUT="${2:?--out needs a value}"; shift 2;;
    --separation) SEPARATION="${2:?--separation needs a value}"; shift 2;;
    --separation-m) SEPARATION_M="${2:?--separation-m needs a value}"; shift 2;;
    --vertical-separation-m) VERTICAL_M="${2:?--vertical-separation-m needs a value}"; shift 2;;
    --slot-s) SLOT_S="${2:?--slot-s needs a value}"; shift 2;;
    --climb-rate) CLIMB="${2:?--climb-rate needs a value}"; shift 2;;
    --descent-rate) DESCENT="${2:?--descent-rate needs a value}"; shift 2;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0;;
    *) die "unknown option '$1' (see --help)";;
  esac
done
[[ "$POLICY" == mwis || "$POLICY" == fifo || "$POLICY" == firstfit ]] || die "--policy: '$POLICY' is not mwis, fifo or firstfit"
# --objective: checked by the preflight below against the objectives' registry (uam_planner.objectives)
[[ "$BASELINE_ORDER" == arrival || "$BASELINE_ORDER" == priority ]] || die "--baseline-order: '$BASELINE_ORDER' is not arrival or priority"
[[ "$PRIORITY_SHARE" =~ ^(0(\.[0-9]+)?|1(\.0+)?)$ ]] || die "--priority-share: '$PRIORITY_SHARE' is not a number in [0, 1]"
[[ "$HORIZON" =~ ^[0-9]+$ ]] && (( HORIZON >= 1 && HORIZON <= 100 )) || die "--horizon: '$HORIZON' is not an integer in [1, 100]"
[[ "$COMMIT_AHEAD" == true || "$COMMIT_AHEAD" == false ]] || die "--commit-ahead: '$COMMIT_AHEAD' is not true or false"
[[ "$REACTION" == true || "$REACTION" == false ]] || die "--reaction: '$REACTION' is not true or false"
[[ -z "$REPLAN_POLICY" || "$REPLAN_POLICY" == mwis || "$REPLAN_POLICY" == firstfit ]] || die "--replan-policy: '$REPLAN_POLICY' is not mwis or firstfit"
[[ "$LEAD_TIME" =~ ^[0-9]+(\.[0-9]+)?$ ]] || die "--lead-time: '$LEAD_TIME' is not a number of seconds >= 0"
[[ "$MODE" == lockstep || "$MODE" == realtime ]] || die "--mode: '$MODE' is not lockstep or realtime"
[[ "$RERUN" =~ ^(off|save|spawn|connect)$ ]] || die "--rerun: '$RERUN' is not off, save, spawn or connect"
[[ "$RATE" =~ ^[0-9]+(\.[0-9]+)?$ ]] || die "--rate: '$RATE' is not a number >= 0"
[[ "$DURATION" =~ ^[0-9]+(\.[0-9]+)?$ ]] || die "--duration: '$DURATION' is not a number of seconds"
[[ "$SEED" =~ ^[0-9]+$ ]] || die "--seed: '$SEED' is not an integer >= 0"
[[ "$FOXGLOVE_PORT" =~ ^[0-9]+$ ]] && (( FOXGLOVE_PORT <= 65535 )) || die "--foxglove-port: '$FOXGLOVE_PORT' is not a port 0..65535"
[[ "$CONFORMANCE" =~ ^(auto|true|false)$ ]] || die "--conformance: '$CONFORMANCE' is not auto, true or false"
[[ "$USS_PORT" =~ ^[0-9]+$ ]] && (( USS_PORT <= 65535 )) || die "--uss-port: '$USS_PORT' is not a port 0..65535"
[[ "$USS_AUTH" == verify || "$USS_AUTH" == off ]] || die "--uss-auth: '$USS_AUTH' is not verify or off"
[[ -z "$USS_AUTH_KEY" || -f "$USS_AUTH_KEY" ]] || die "--uss-auth-key: no file '$USS_AUTH_KEY'"
[[ -z "$DSS_TOKEN_FILE" || -f "$DSS_TOKEN_FILE" ]] || die "--dss-token-file: no file '$DSS_TOKEN_FILE'"
[[ "$RTF" =~ ^[0-9]+(\.[0-9]+)?$ ]] || die "--rtf: '$RTF' is not a positive number"
[[ -z "$SEPARATION" || "$SEPARATION" == sphere || "$SEPARATION" == cylinder ]] || die "--separation: '$SEPARATION' is not sphere or cylinder"
for _flag in "separation-m:$SEPARATION_M" "vertical-separation-m:$VERTICAL_M" "slot-s:$SLOT_S" \
             "climb-rate:$CLIMB" "descent-rate:$DESCENT" "spatial-buffer-m:$SPATIAL_BUFFER" \
             "temporal-buffer-s:$TEMPORAL_BUFFER" "wind:$WIND" "wind-from:$WIND_FROM" "gust:$GUST" \
             "speed-error:$SPEED_ERROR" "delay-mean:$DELAY_MEAN" "vertical-gust:$VERTICAL_GUST" \
             "altitude-error:$ALTITUDE_ERROR" "reaction-period:$REACTION_PERIOD" "probe:$PROBE" \
             "probe-margin:$PROBE_MARGIN"; do
  [[ "${_flag#*:}" =~ ^[0-9]+(\.[0-9]+)?$ ]] || die "--${_flag%%:*}: '${_flag#*:}' is not a number >= 0"
done
if [[ "$REACTION" != true ]] && awk -v p="$REACTION_PERIOD" 'BEGIN { exit !(p + 0 > 0) }'; then
  die "--reaction-period: '$REACTION_PERIOD' needs --reaction true (the planner reacts only then)"
fi
if [[ "$REACTION" != true ]] && awk -v p="$PROBE" 'BEGIN { exit !(p + 0 > 0) }'; then
  die "--probe: '$PROBE' needs --reaction true (the probe runs at the planner's reactions)"
fi
if awk -v p="$PROBE" -v m="$PROBE_MARGIN" 'BEGIN { exit !(m + 0 > 0 && p + 0 <= 0) }'; then
  die "--probe-margin: '$PROBE_MARGIN' needs --probe > 0 (the margin is the probe's)"
fi
# as floats: ROS parameters typed double refuse an integer given on the command line
f() { [[ "$1" == *.* ]] && echo "$1" || echo "$1.0"; }
[[ -f "$NETWORK" ]] || die "--network: no file '$NETWORK'"
[[ -z "$DEMAND" || -f "$DEMAND" ]] || die "--demand: no file '$DEMAND'"
[[ -z "$PRIORITY_GRANTS" || -f "$PRIORITY_GRANTS" ]] || die "--priority-grants: no file '$PRIORITY_GRANTS'"
[[ -z "$CONSTRAINTS" || -f "$CONSTRAINTS" ]] || die "--constraints: no file '$CONSTRAINTS'"

# the set-up shows only the steps it has to do, with their progress (a first run takes minutes;
# its output went to a temporary file and the terminal showed nothing for 8 min)
UAM_SETUP_BRIEF=1 bash scripts/setup.sh || die "setup failed (above; its full log: log/setup.log)"
# shellcheck disable=SC1091
source scripts/env.sh
# auto: the monitor runs when the fleet can deviate from its plans or the planner reacts to its
# reports (the one rule: uam_contract.disturbances, which the launch file reads too)
CONFORMANCE=$(python -m uam_contract.disturbances "$CONFORMANCE" "$REACTION" "$WIND" "$GUST" "$SPEED_ERROR" \
  "$DELAY_MEAN" "$VERTICAL_GUST" "$ALTITUDE_ERROR") || die "--conformance: could not be decided (above)"
if [[ "$BACKEND" == list ]]; then
  echo "MWIS backends (this script runs --backend exact unless told otherwise; the solver node"
  echo "started on its own uses default_backend from config/solver.yaml, 'auto'):"
  python -m uam_solvers.registry
  exit 0
fi
# The values every node will start with, checked against the nodes' own parameter tables, and the
# input files loaded by the libraries' own loaders, in one process before any node starts (a wrong
# value otherwise ended a started graph minutes later, its reason in one node's log). Prints the
# separation model the network was built for (uam_planner.network.Network.separation_model).
AIRSPACE=(-p "separation_m:=$(f "$SEPARATION_M")" -p "vertical_separation_m:=$(f "$VERTICAL_M")"
          -p "departure_slot_s:=$(f "$SLOT_S")")
SOLVER_P=(--params-file config/solver.yaml -p "default_backend:=$BACKEND")
PLANNER_P=(--params-file config/planner.yaml -p "network:=$NETWORK" \
  -p "policy:=$POLICY" -p "backend:=$BACKEND" -p "seed:=$SEED" "${AIRSPACE[@]}" \
  -p "objective:=$OBJECTIVE" -p "baseline_order:=$BASELINE_ORDER" -p "horizon_epochs:=$HORIZON" \
  -p "commit_ahead:=$COMMIT_AHEAD" -p "reaction:=$REACTION" -p "conflict_probe_s:=$(f "$PROBE")" -p "conflict_probe_margin_m:=$(f "$PROBE_MARGIN")" ${REPLAN_POLICY:+-p "replan_policy:=$REPLAN_POLICY"} \
  -p "climb_rate_mps:=$(f "$CLIMB")" -p "descent_rate_mps:=$(f "$DESCENT")" \
  -p "spatial_buffer_m:=$(f "$SPATIAL_BUFFER")" -p "temporal_buffer_s:=$(f "$TEMPORAL_BUFFER")" \
  ${CONSTRAINTS:+-p "constraints_file:=$CONSTRAINTS"})
# F3548 mode: with the USS serving, the planner keeps the volumes it publishes disjoint
(( USS_PORT > 0 )) && PLANNER_P+=(-p "intent_volume_piece_s:=$(f "$VOLUME_PIECE")")
GENERATOR_P=(--params-file config/request_generator.yaml \
  -p "network:=$NETWORK" -p "rate:=$RATE" -p "seed:=$SEED" -p "priority_share:=$(f "$PRIORITY_SHARE")" \
  -p "lead_time_s:=$(f "$LEAD_TIME")" \
  ${DEMAND:+-p "demand_file:=$DEMAND"})
RECORDER_P=(-p "network:=$NETWORK" -p "rerun:='$RERUN'" -p "foxglove_port:=$FOXGLOVE_PORT" "${AIRSPACE[@]}")
USS_P=(-p "port:=$USS_PORT" -p "network:=$NETWORK" -p "separation_m:=$(f "$SEPARATION_M")" \
  -p "vertical_separation_m:=$(f "$VERTICAL_M")" -p "volume_piece_s:=$(f "$VOLUME_PIECE")" \
  ${DSS_URL:+-p "dss_url:=$DSS_URL"} ${DSS_TOKEN_FILE:+-p "dss_token_file:=$DSS_TOKEN_FILE"} \
  ${DSS_AUTH_URL:+-p "dss_auth_url:=$DSS_AUTH_URL"})
SIMULATOR_P=(--params-file config/simulator.yaml -p "duration_s:=$(f "$DURATION")" \
  -p "mode:=$MODE" -p "real_time_factor:=$(f "$RTF")" \
  -p "disturbance_seed:=$SEED" -p "wind_speed_mps:=$(f "$WIND")" \
  -p "wind_from_deg:=$(f "$WIND_FROM")" -p "gust_std_mps:=$(f "$GUST")" -p "speed_error:=$(f "$SPEED_ERROR")" \
  -p "delay_mean_s:=$(f "$DELAY_MEAN")" -p "vertical_gust_std_mps:=$(f "$VERTICAL_GUST")" \
  -p "altitude_error_m:=$(f "$ALTITUDE_ERROR")" -p "reaction_period_s:=$(f "$REACTION_PERIOD")")
USS_CHECK=()  # the USS server's parameters, only when it runs
(( USS_PORT > 0 )) && USS_CHECK=(--node uss "${USS_P[@]}")
NET_MODEL="$(python -m uam_sim.preflight --prog run_fleet --backend "$BACKEND" --network "$NETWORK" \
  --demand "$DEMAND" --constraints "$CONSTRAINTS" --node solver "${SOLVER_P[@]}" \
  --node planner "${PLANNER_P[@]}" -p "separation_model:=$SEPARATION" --node request_generator "${GENERATOR_P[@]}" \
  --node recorder "${RECORDER_P[@]}" --node simulator "${SIMULATOR_P[@]}" "${USS_CHECK[@]}")" || exit 2
if [[ -z "$SEPARATION" ]]; then
  SEPARATION=$NET_MODEL
elif [[ "$SEPARATION" != "$NET_MODEL" ]]; then
  echo "run_fleet: WARNING: --separation $SEPARATION contradicts $NETWORK, built for $NET_MODEL$([[ $NET_MODEL == cylinder ]] && echo ' (its flight levels are closer than the sphere: they separate nothing)'); running with $SEPARATION as asked" >&2
fi

if [[ -z "$OUT" ]]; then
  # mktemp creates the folder atomically with a random suffix: two runs started in the same second
  # never share a folder (and never write one MCAP file together)
  mkdir -p "${UAM_RUNS_DIR:-runs}"
  OUT="$(mktemp -d "${UAM_RUNS_DIR:-runs}/$(date +%Y%m%d-%H%M%S)-$POLICY-$BACKEND-r$RATE-s$SEED-XXXX")"
fi
mkdir -p "$OUT"
OUT="$(cd "$OUT" && pwd)"
MCAP="$OUT/run.mcap" RRD="$OUT/run.rrd"
if [[ -z "${ROS_DOMAIN_ID:-}" ]]; then
  # Claim a domain id nobody else on this machine uses (the test harness takes the same lock files),
  # so two runs, or a run and a test session, never hear each other. Held until this script exits.
  for id in $(seq 20 100); do
    exec {DOMAIN_LOCK_FD}>"/tmp/uam-ros-domain-$id.lock"
    if flock -n "$DOMAIN_LOCK_FD"; then export ROS_DOMAIN_ID=$id; break; fi
    exec {DOMAIN_LOCK_FD}>&-
  done
  [[ -n "${ROS_DOMAIN_ID:-}" ]] || die "no free ROS domain id in 20..100"
fi
echo "run_fleet: policy $POLICY, backend $BACKEND, rate $RATE per 30 s, ${DURATION} s, seed $SEED, network $NETWORK"
if [[ "$SEPARATION" == cylinder ]]; then _sep="cylinder H $SEPARATION_M m, V $VERTICAL_M m"; else _sep="sphere $SEPARATION_M m"; fi
echo "run_fleet: airspace: separation $_sep, departure slot $SLOT_S s"
echo "run_fleet: outputs in $OUT (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
# the run's domain, for the tools that join it (python -m uam_planner.nodes.constraint_client --run $OUT)
echo "ROS_DOMAIN_ID=$ROS_DOMAIN_ID" > "$OUT/run.env"
# the run's airspace authority: a new key pair each run; the planner takes live constraint
# updates signed with it only (uam_planner.authority; docs/constraints.md)
python -m uam_planner.authority new "$OUT/authority" >/dev/null || die "no airspace authority key pair (above)"
if (( USS_PORT > 0 )); then  # the USS's own authority (not an admin): it passes peers' intents to the planner and
  # puts the flight plans of its flight_planning interface (operator flight_planning) in its name
  python -m uam_planner.authority new "$OUT/authority" --id uss-peers --not-admin --add \
    --operator flight_planning >/dev/null \
    || die "no key pair for the USS's authority (above)"
fi
echo "run_fleet: live constraints: python -m uam_planner.nodes.constraint_client add FEATURE.geojson --run $OUT"
# the priority classes each operator may ask for (uam_planner.grants): given, or the generator's
# own class (its priority_class in config/request_generator.yaml) and 0 for any other operator
if [[ -z "$PRIORITY_GRANTS" ]]; then
  PRIORITY_GRANTS="$OUT/priority_grants.yaml"
  python -c 'import sys, yaml
from uam_planner.grants import PriorityGrants
gen = yaml.safe_load(open("config/request_generator.yaml"))["request_generator"]["ros__parameters"]
sys.stdout.write(PriorityGrants(0, {gen["operator_id"]: int(gen["priority_class"])}).as_yaml())' > "$PRIORITY_GRANTS" \
    || die "no priority grants file (above)"
fi
python -c 'import sys; from uam_planner.grants import PriorityGrants; PriorityGrants.load(sys.argv[1])' "$PRIORITY_GRANTS" \
  || die "--priority-grants: $PRIORITY_GRANTS is not a grants file (above)"
USS_AUTH_ARGS=(-p "auth:=$USS_AUTH")
if (( USS_PORT > 0 )) && [[ "$USS_AUTH" == verify ]]; then
  if [[ -z "$USS_AUTH_KEY" ]]; then
    # no auth server given: a development one, its key pair and a token in the run's folder
    python -m uam_sim.uss_server keys "$OUT/uss-auth" >/dev/null || die "--uss-auth verify: no development key pair (above)"
    USS_AUTH_KEY="$OUT/uss-auth/public.pem"
    (umask 077; python -m uam_sim.uss_server token --key "$OUT/uss-auth/private.pem" --lifetime-s 86400 \
      ${USS_AUDIENCE:+--audience "${USS_AUDIENCE%%,*}"} >"$OUT/uss-auth/token") || die "--uss-auth verify: no development token (above)"
    echo "run_fleet: USS access tokens: development key pair in $OUT/uss-auth; a token (both scopes, 24 h) in $OUT/uss-auth/token; more: python -m uam_sim.uss_server token --key $OUT/uss-auth/private.pem"
  fi
  USS_AUTH_ARGS+=(-p "auth_key:=$USS_AUTH_KEY")
elif (( USS_PORT > 0 )); then
  echo "run_fleet: WARNING: --uss-auth off: the F3548 USS server answers every caller without an access token" >&2
fi
[[ -n "$USS_AUDIENCE" ]] && USS_AUTH_ARGS+=(-p "auth_audience:=$USS_AUDIENCE")

PIDS=() NAMES=()
# Each node is the installed executable itself (what `ros2 run` would start, without the ros2
# process in between, which would not pass the parent-death signal on), under setpriv so that the
# kernel sends it SIGTERM if this script dies, even by SIGKILL.
WATCH_PARENT=()
if setpriv --pdeathsig TERM true 2>/dev/null; then WATCH_PARENT=(setpriv --pdeathsig TERM --)
else echo "run_fleet: setpriv --pdeathsig is unavailable; if this script is killed, stop the nodes by hand" >&2; fi
start() {  # start <pkg> <exe> <log name> [ros args...]; NODE_NICE=N start ... lowers its priority
  local pkg=$1 exe=$2 name=$3; shift 3
  local -a prio=()
  [[ -n "${NODE_NICE:-}" ]] && prio=(nice -n "$NODE_NICE")
  # the domain lock stays with this script: a node must not inherit its descriptor (a solver left
  # running would otherwise keep the domain id claimed)
  if [[ -n "${DOMAIN_LOCK_FD:-}" ]]; then
    "${WATCH_PARENT[@]}" "${prio[@]}" "$ROOT/install/$pkg/lib/$pkg/$exe" --ros-args "$@" >"$OUT/$name.log" 2>&1 {DOMAIN_LOCK_FD}>&- &
  else
    "${WATCH_PARENT[@]}" "${prio[@]}" "$ROOT/install/$pkg/lib/$pkg/$exe" --ros-args "$@" >"$OUT/$name.log" 2>&1 &
  fi
  PIDS+=($!) NAMES+=("$name")
}
alive() {  # a child that exited stays a zombie until reaped, and kill -0 still succeeds on it
  # (LAST_STATE: the state it was last seen in, for the message of a node that does not stop:
  # twice a "did not stop" node was gone when described a moment later, state unknown)
  LAST_STATE=$(cut -d' ' -f3 /proc/$1/stat 2>/dev/null)
  [[ -n "$LAST_STATE" ]] && [[ "$LAST_STATE" != Z ]]
}
describe() {  # what a node that does not stop is doing: its threads' states and kernel waits
  local pid=$1 t
  echo "run_fleet:   pid $pid: state $(cut -d' ' -f3 /proc/$pid/stat 2>/dev/null), wchan $(cat /proc/$pid/wchan 2>/dev/null)"
  for t in /proc/$pid/task/*; do
    [[ -r $t/stat ]] || continue
    echo "run_fleet:   thread ${t##*/} ($(cat $t/comm 2>/dev/null)): state $(sed 's/.*) //' $t/stat 2>/dev/null | cut -d' ' -f1), wchan $(cat $t/wchan 2>/dev/null)"
  done
}
stop_all() {
  local sig=${1:-INT}
  # The niced observers (recorder, conformance monitor) get their share back for the stop, where
  # the system allows it (lowering a nice value needs privileges; otherwise this does nothing): at
  # nice 19 under load the recorder's drain and close (~1 s of CPU) took more than 10 s.
  for pid in "${PIDS[@]}"; do renice -n 0 -p "$pid" >/dev/null 2>&1 || true; done
  for pid in "${PIDS[@]}"; do kill -"$sig" "$pid" 2>/dev/null || true; done
  local t0=$SECONDS
  local i limit
  for i in "${!PIDS[@]}"; do
    # every node gets 10 s; the recorder, which still has to write out the recording (lost if it
    # is killed), gets RECORDER_STOP_S
    limit=10; [[ "${NAMES[$i]}" == recorder ]] && limit=$RECORDER_STOP_S
    while alive "${PIDS[$i]}" && (( SECONDS < t0 + limit )); do sleep 0.1; done
    if alive "${PIDS[$i]}"; then
      echo "run_fleet: node '${NAMES[$i]}' (pid ${PIDS[$i]}) did not stop within $limit s (last seen in state '$LAST_STATE'); killing it" >&2
      describe "${PIDS[$i]}" >&2
      kill -KILL "${PIDS[$i]}" 2>/dev/null || true
    fi
  done
  local rc
  for i in "${!PIDS[@]}"; do
    rc=0; wait "${PIDS[$i]}" 2>/dev/null || rc=$?
    (( rc == 0 )) || echo "run_fleet: node '${NAMES[$i]}' exited with code $rc" >&2
  done
}
interrupted() { echo; echo "run_fleet: interrupted; stopping every node"; stop_all INT; trap - INT TERM HUP; INTERRUPTED=1; }
INTERRUPTED=0
trap interrupted INT TERM HUP

# (the parameters checked above, and those that name this run's files)
start uam_solvers solver solver "${SOLVER_P[@]}"
start uam_planner planner planner "${PLANNER_P[@]}" -p "separation_model:=$SEPARATION" \
  -p "journal:=$OUT/planner-journal.jsonl" -p "authorities_file:=$OUT/authority/authorities.yaml" \
  -p "priority_grants:=$PRIORITY_GRANTS"
start uam_sim request_generator request_generator "${GENERATOR_P[@]}"
# the recorder writes the run's airspace into the MCAP (uam_airspace metadata): the analysis audits in it.
# It subscribes to the fleet state (which starts the simulator) only once it hears these topics'
# publishers, so even a run stopped at once records the planner's and the generator's messages.
RECORDER_WAITS="$(python -c 'from uam_contract.names import RECORDER_WAITS_FOR as w; print(",".join(w))')"
# the run's choices, written by the recorder into the MCAP (uam_run metadata) for the analysis' header
USS_CHOICE=()  # the USS server's auth, only when it runs (an 'off' run says so in its header)
(( USS_PORT > 0 )) && USS_CHOICE=(uss_auth="$USS_AUTH")
RUN_CHOICES="$(python -m uam_contract.run_choices policy="$POLICY" backend="$BACKEND" objective="$OBJECTIVE" \
  baseline_order="$BASELINE_ORDER" rate="$RATE" seed="$SEED" priority_share="$PRIORITY_SHARE" horizon="$HORIZON" \
  commit_ahead="$COMMIT_AHEAD" lead_time_s="$LEAD_TIME" departure_slot_s="$SLOT_S" spatial_buffer_m="$SPATIAL_BUFFER" \
  temporal_buffer_s="$TEMPORAL_BUFFER" reaction="$REACTION" reaction_period_s="$REACTION_PERIOD" probe_s="$PROBE" \
  probe_margin_m="$PROBE_MARGIN" wind_mps="$WIND" wind_from_deg="$WIND_FROM" gust_mps="$GUST" \
  speed_error="$SPEED_ERROR" delay_mean_s="$DELAY_MEAN" vertical_gust_mps="$VERTICAL_GUST" \
  altitude_error_m="$ALTITUDE_ERROR" "${USS_CHOICE[@]}")"
NODE_NICE=$RECORDER_NICE
start uam_sim recorder recorder "${RECORDER_P[@]}" -p "separation_model:=$SEPARATION" -p "output:=$MCAP" \
  -p "rerun_rrd:=$RRD" -p "wait_for_publishers:=[$RECORDER_WAITS]" \
  -p "run_choices:='$RUN_CHOICES'"
REC_PID=${PIDS[-1]}
NODE_NICE=
# issue 23: compares every fleet state with the approved plans, publishes uam/conformance (recorded);
# an observer like the recorder, so it runs at the recorder's priority
SIM_WAITS=recorder
if [[ "$CONFORMANCE" == true ]]; then
  NODE_NICE=$RECORDER_NICE
  start uam_sim conformance_monitor conformance_monitor
  NODE_NICE=
  SIM_WAITS=recorder,conformance_monitor
fi
if (( USS_PORT > 0 )); then  # the F3548 USS-USS interface (docs/f3548.md)
  # it serves the planner's own record (its journal), not the topics anyone can publish
  start uam_sim uss uss "${USS_P[@]}" -p "separation_model:=$SEPARATION" "${USS_AUTH_ARGS[@]}" \
    -p "journal:=$OUT/planner-journal.jsonl" -p "authority_key:=$OUT/authority/uss-peers.key.pem"
  echo "run_fleet: F3548 operational intents on http://127.0.0.1:$USS_PORT/uss/v1/operational_intents/{id} (ids: /uam_fleet/v1/operational_intents; auth $USS_AUTH)"
fi
start uam_sim simulator simulator "${SIMULATOR_P[@]}" -p "wait_for_subscribers:=[$SIM_WAITS]"
SIM_PID=${PIDS[-1]}
T0=$SECONDS
SIM_RC=0
# What the terminal sees of the running graph: the simulator's progress lines (every
# progress_epochs epochs) and the warnings and errors of the simulator and the planner, e.g. a
# stall waiting for the fleet state (a lockstep run was otherwise silent for minutes, the reason
# in planner.log). Each log is read on from the last complete line seen; at most 5 warnings per
# look and log. No line for STALL_S seconds is announced, with each log's last line.
declare -A NEWS_LINE=()
NEWS_T=$SECONDS STALL_S=60
news() {
  local name log n at
  for name in simulator planner; do
    log="$OUT/$name.log"; at=${NEWS_LINE[$name]:-0}
    n=$(wc -l 2>/dev/null <"$log") || continue
    (( n > at )) || continue
    NEWS_LINE[$name]=$n NEWS_T=$SECONDS
    sed -n "$((at + 1)),${n}p" "$log" | awk -v who="$name" -v file="$log" '
      /^\[INFO\].*\]: progress: / { sub(/^[^]]*\] [^]]*\] [^]]*\]: /, ""); print "run_fleet: " who ": " $0; next }
      /^\[(WARN|ERROR)\]/ { if (++k <= 5) { sub(/^[^]]*\] [^]]*\] [^]]*\]: /, ""); print "run_fleet: " who ": " $0 } }
      END { if (k > 5) print "run_fleet: " who ": (" k - 5 " more warnings in " file ")" }'
  done
  if (( SECONDS - NEWS_T >= STALL_S )); then
    echo "run_fleet: no news from the simulator or the planner for $((SECONDS - NEWS_T)) s; still waiting. Last lines:"
    for name in simulator planner; do echo "run_fleet:   $name: $(tail -n 1 "$OUT/$name.log" 2>/dev/null)"; done
    NEWS_T=$SECONDS
  fi
}
# Watch the graph: a node that dies while the simulator runs ends the run with its log's tail.
while alive "$SIM_PID" && (( INTERRUPTED == 0 )); do
  news
  for i in "${!PIDS[@]}"; do
    if (( INTERRUPTED == 0 )) && [[ "${PIDS[$i]}" != "$SIM_PID" && "${NAMES[$i]}" != solver ]] && ! alive "${PIDS[$i]}" \
        && ! grep -q "run finished" "$OUT/simulator.log" 2>/dev/null; then
      # a stop signal trapped while this check ran stopped the node itself: not a failure
      (( INTERRUPTED == 0 )) || break
      echo "run_fleet: node '${NAMES[$i]}' exited before the end of the run; its log ($OUT/${NAMES[$i]}.log) ends with:" >&2
      tail -n 5 "$OUT/${NAMES[$i]}.log" >&2
      stop_all INT
      exit 1
    fi
  done
  sleep 0.5 & wait $! || true
done
wait "$SIM_PID" 2>/dev/null || SIM_RC=$?
news
if (( INTERRUPTED == 0 )); then
  # The recorder closes the file by itself once the simulator announced the end and the last
  # messages are in; planner and generator exit on that announcement too; the solver is a server
  # and is stopped here.
  deadline=$((SECONDS + 60))
  while alive "$REC_PID" && (( SECONDS < deadline )); do sleep 0.1; done
  stop_all INT
fi
trap - INT TERM HUP
echo "run_fleet: node graph finished in $((SECONDS - T0)) s wall (simulator exit code $SIM_RC)"
grep -h "run finished" "$OUT/simulator.log" || true
echo "run_fleet: recording: $MCAP"
# The view is the .rrd: `rerun run.mcap` opens Rerun's generic MCAP reader (dots and raw fields)
if [[ -f "$RRD" ]]; then
  echo "run_fleet: view:      rerun $RRD   (not 'rerun $MCAP': Rerun's generic MCAP reader, see docs/views.md)"
else
  echo "run_fleet: view:      python -m uam_sim.rerun_log $MCAP --network $NETWORK && rerun $RRD"
fi
echo "run_fleet: node logs: $OUT/*.log"
ANALYSIS_RC=0
if [[ -f "$MCAP" ]]; then
  # exit code 2: a loss of separation; 3: the recording lacks plans it should hold (not verified)
  python -m uam_sim.analysis "$MCAP" --network "$NETWORK" | tee "$OUT/summary.txt" || ANALYSIS_RC=$?
else
  echo "run_fleet: no recording was written; see $OUT/recorder.log" >&2
  exit 1
fi
(( INTERRUPTED == 0 )) || exit 130
(( ANALYSIS_RC == 0 )) || exit "$ANALYSIS_RC"
exit "$SIM_RC"
