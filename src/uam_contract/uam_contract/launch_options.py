"""The options of the two launchers, one table: ``scripts/run_fleet.sh`` (flags) and
``launch/uam.launch.py`` (launch arguments, for /opt/ros/jazzy users).

Each row names the run_fleet.sh flag and its shell variable, the launch argument, the default
(as text, as both launchers take it) and what it means. ``only`` marks the few options that one
launcher has for a reason of its own: the launch file has a ``namespace`` and a ``config_dir``
(run_fleet.sh runs from the checkout and claims a ROS domain instead), run_fleet.sh a
``--recorder-nice`` (the launch file runs the recorder at nice 19 by a prefix). The launch file
builds its arguments from this table; ``test/test_launchers.py`` holds run_fleet.sh's usage text,
flags and defaults to it, so an option cannot exist in one launcher and not the other.
"""

from __future__ import annotations

from dataclasses import dataclass

from uam_contract import defaults as D


@dataclass(frozen=True)
class LaunchOption:
    flag: str          # run_fleet.sh flag ("" = launch file only)
    var: str           # run_fleet.sh shell variable
    arg: str           # launch argument ("" = run_fleet.sh only)
    default: str
    help: str
    only: str = ""     # "", "run_fleet" or "launch"


LAUNCH_OPTIONS: tuple[LaunchOption, ...] = (
    LaunchOption("--backend", "BACKEND", "backend", "exact", "MWIS backend of the solver and the planner"),
    LaunchOption("--policy", "POLICY", "policy", "mwis", "mwis, fifo or firstfit"),
    LaunchOption("--objective", "OBJECTIVE", "objective", "paper",
                 "what the MWIS maximises: a registered objective (python -m uam_planner.objectives lists "
                 "them: paper, count, delay, priority, fair, ...; docs/objectives.md)"),
    LaunchOption("--baseline-order", "BASELINE_ORDER", "baseline_order", "arrival",
                 "order of fifo and firstfit: arrival or priority"),
    LaunchOption("--horizon", "HORIZON", "horizon_epochs", "1",
                 "epochs the MWIS plans jointly (rolling horizon; 1 = the paper's)"),
    LaunchOption("--commit-ahead", "COMMIT_AHEAD", "commit_ahead", "false",
                 "with --horizon > 1, commit the horizon's later departures now as reservations"),
    LaunchOption("--reaction", "REACTION", "reaction", "false",
                 "the planner updates a nonconforming flight's intent (reports checked against its own view)"),
    LaunchOption("--reaction-period", "REACTION_PERIOD", "reaction_period_s", "0",
                 "with --reaction true, the planner also reacts every this many seconds between epochs "
                 "(a multiple of the simulator's step, less than the epoch; 0 = at epochs only)"),
    LaunchOption("--probe", "PROBE", "conflict_probe_s", "0",
                 "with --reaction true, the conflict probe's look-ahead [s]: at each reaction the planner "
                 "projects airborne flights from their sightings and updates pairs that would lose "
                 "separation within it (docs/disturbances.md; 0 = off)"),
    LaunchOption("--probe-margin", "PROBE_MARGIN", "conflict_probe_margin_m", "0",
                 "with --probe, the probe's margin [m]: it predicts losses of the minimum + this and "
                 "deconflicts its updates with at least that (0 = the true minimum)"),
    LaunchOption("--replan-policy", "REPLAN_POLICY", "replan_policy", "",
                 "re-plan of the flights a constraint update affects: mwis or firstfit; default: the policy's"),
    LaunchOption("--priority-share", "PRIORITY_SHARE", "priority_share", "0",
                 "share of random requests of priority class 1 (e.g. 0.05)"),
    LaunchOption("--lead-time", "LEAD_TIME", "lead_time_s", "0",
                 "requests are filed this long before their earliest departure [s]"),
    LaunchOption("--rate", "RATE", "rate", "10", "requests per 30 s"),
    LaunchOption("--duration", "DURATION", "duration", "3500", "simulated seconds"),
    LaunchOption("--seed", "SEED", "seed", "0", "seed of the demand and of stochastic solvers"),
    LaunchOption("--network", "NETWORK", "network", "config/networks/singapore.yaml", "routing network file"),
    LaunchOption("--separation", "SEPARATION", "separation", "",
                 "separation model: sphere (the paper's) or cylinder; default: the network's own "
                 "(a layered network declares cylinder), else sphere"),
    LaunchOption("--separation-m", "SEPARATION_M", "separation_m", D.as_text(D.SEPARATION_M),
                 "separation minimum, the cylinder's horizontal H [m]"),
    LaunchOption("--vertical-separation-m", "VERTICAL_M", "vertical_separation_m", D.as_text(D.VERTICAL_SEPARATION_M),
                 "the cylinder's vertical minimum V [m]"),
    LaunchOption("--slot-s", "SLOT_S", "slot_s", D.as_text(D.DEPARTURE_SLOT_S), "departure slot [s]; 0 = depart at the epoch time"),
    LaunchOption("--climb-rate", "CLIMB", "climb_rate", D.as_text(D.CLIMB_RATE_MPS), "vertical climb rate at vertiports [m/s]"),
    LaunchOption("--descent-rate", "DESCENT", "descent_rate", D.as_text(D.DESCENT_RATE_MPS), "vertical descent rate at vertiports [m/s]"),
    LaunchOption("--demand", "DEMAND", "demand_file", "", "replay a demand file instead of random requests"),
    LaunchOption("--priority-grants", "PRIORITY_GRANTS", "priority_grants", "",
                 "the priority classes each operator may ask for (uam_planner.grants); '' = run_fleet.sh: "
                 "the generator's class and 0 for any other operator; the launch file: every class taken"),
    LaunchOption("--constraints", "CONSTRAINTS", "constraints_file", "",
                 "airspace constraints the planner plans around (docs/constraints.md)"),
    LaunchOption("--spatial-buffer-m", "SPATIAL_BUFFER", "spatial_buffer_m", "0",
                 "planning buffer on the separation [m] (docs/disturbances.md; audits keep the minimum)"),
    LaunchOption("--temporal-buffer-s", "TEMPORAL_BUFFER", "temporal_buffer_s", "0",
                 "temporal planning buffer [s] (docs/disturbances.md)"),
    LaunchOption("--wind", "WIND", "wind_speed_mps", "0", "steady wind speed [m/s] the simulator flies in"),
    LaunchOption("--wind-from", "WIND_FROM", "wind_from_deg", "270",
                 "direction the steady wind blows from [deg from north]"),
    LaunchOption("--gust", "GUST", "gust_std_mps", "0", "gust standard deviation per horizontal component [m/s]"),
    LaunchOption("--speed-error", "SPEED_ERROR", "speed_error", "0",
                 "per-flight airspeed error bound, uniform (0.1 = +-10 %)"),
    LaunchOption("--delay-mean", "DELAY_MEAN", "delay_mean_s", "0", "mean departure delay [s] (exponential)"),
    LaunchOption("--vertical-gust", "VERTICAL_GUST", "vertical_gust_std_mps", "0",
                 "vertical gust standard deviation [m/s] (docs/disturbances.md)"),
    LaunchOption("--altitude-error", "ALTITUDE_ERROR", "altitude_error_m", "0",
                 "per-flight altitude-hold error bound, uniform [m]"),
    LaunchOption("--conformance", "CONFORMANCE", "conformance", "auto",
                 "start the conformance monitor: true, false, or auto = only when a disturbance is set "
                 "(an undisturbed fleet flies its plans exactly; the monitor costs more CPU than any other node)"),
    LaunchOption("--mode", "MODE", "mode", "lockstep", "lockstep or realtime"),
    LaunchOption("--rtf", "RTF", "rtf", "1", "real-time factor in realtime mode"),
    LaunchOption("--rerun", "RERUN", "rerun", "save", "off, save, spawn or connect"),
    LaunchOption("--foxglove-port", "FOXGLOVE_PORT", "foxglove_port", "0",
                 "serve a live Foxglove WebSocket view on this port (0 = off)"),
    LaunchOption("--uss-port", "USS_PORT", "uss_port", "0",
                 "serve the plans as F3548 operational intents over HTTP on this port (0 = off; docs/f3548.md)"),
    LaunchOption("--volume-piece", "VOLUME_PIECE", "volume_piece_s", "5",
                 "with --uss-port: the longest time window of one published Volume4D [s]; the planner then keeps "
                 "the published volumes of every two flights disjoint too (F3548 mode; docs/f3548.md)"),
    LaunchOption("--dss-url", "DSS_URL", "dss_url", "",
                 "with --uss-port: the DSS whose operational intent references the USS keeps in step with its "
                 "intents ('' = none; docs/f3548.md, DSS reference management)"),
    LaunchOption("--dss-token-file", "DSS_TOKEN_FILE", "dss_token_file", "",
                 "with --dss-url: a file holding the bearer token sent to the DSS (or --dss-auth-url)"),
    LaunchOption("--dss-auth-url", "DSS_AUTH_URL", "dss_auth_url", "",
                 "with --dss-url: an auth server's token endpoint asked for each token (InterUSS's dummy OAuth)"),
    LaunchOption("--uss-auth", "USS_AUTH", "uss_auth", "verify",
                 "the USS server's access tokens: verify (checked against --uss-auth-key) or off (announced)"),
    LaunchOption("--uss-auth-key", "USS_AUTH_KEY", "uss_auth_key", "",
                 "the auth server's public key (PEM or JWKS) for --uss-auth verify; '' = run_fleet.sh makes a "
                 "development pair in <out>/uss-auth (the launch file needs one)"),
    LaunchOption("--uss-audience", "USS_AUDIENCE", "uss_audience", "",
                 "audiences a token may name, comma-separated ('' = localhost and 127.0.0.1)"),
    LaunchOption("--out", "OUT", "out", "", "output folder (run.mcap, run.rrd, logs); default a new folder under runs/"),
    LaunchOption("--recorder-nice", "RECORDER_NICE", "", "19", "the recorder's nice value", only="run_fleet"),
    LaunchOption("", "", "namespace", "", "namespace of the whole graph", only="launch"),
    LaunchOption("", "", "authorities_file", "", "the airspace authorities whose signed live constraint updates "
                 "the planner takes (uam_planner.authority); '' = none taken (run_fleet.sh makes one per run)",
                 only="launch"),
    LaunchOption("", "", "config_dir", "config", "folder of the parameter files", only="launch"),
)
