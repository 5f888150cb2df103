"""Every node's parameters, one table per node: the contract for declaration, run-time changes and docs.

A :class:`Param` (the one row class of :mod:`uam_contract.validation`, shared with the MWIS
backends' options) says a parameter's name, default (whose type is the parameter's type), meaning,
range or choices, and whether it may change while the node runs. The tables are plain data:
:func:`uam_bringup.params.declare_table` declares a node's table on the node (rclpy), and
``python -m uam_contract.params`` prints them as Markdown (docs/parameters.md). A rule that needs
a library (the known MWIS backends) is named by ``Param.rule`` and supplied by the node.

Numbers given as integers where a float is expected (``-p duration_s:=600``) are accepted: float
parameters are declared with dynamic typing and converted here.
"""

from __future__ import annotations

import sys
from typing import Callable

from uam_contract import defaults as D
from uam_contract.names import RERUN_MODES
from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC, SIM_CLOCK
from uam_contract.validation import Param, choices_text

INT32_MAX = 2**31 - 1


#: the choices as docs/parameters.md writes them (the '' choice as '')
_choices_text = choices_text


def _bool_alias(p: "Param") -> bool:
    """A string parameter with the choice 'off' or 'on', which YAML turns into a boolean."""
    return isinstance(p.default, str) and bool(p.choices) and bool({"off", "on"} & set(p.choices))


#: rclpy's own parameters that would break a running node of this graph: refused at run time
#: (and at start-up: :func:`check_builtins`). With use_sim_time the simulator's timers would wait
#: for the /clock it publishes itself (frozen for good); the other nodes take simulation time from
#: the epoch protocol and never need it.
FROZEN_BUILTINS = {
    "use_sim_time": "parameter use_sim_time: the nodes of this graph take simulation time from the epoch "
                    "protocol; switching to /clock time would freeze the simulator's own timers",
}


# ---- the tables ------------------------------------------------------------------------------------

def _id_rule(value: str) -> str:
    from uam_contract.wire import ID_PATTERN, MAX_ID_LENGTH

    if not ID_PATTERN.fullmatch(value):
        return (f"{value[:MAX_ID_LENGTH]!r} must be 1 to {MAX_ID_LENGTH} characters of "
                "letters, digits, '_', '-' and '.'")
    return ""


def _nonempty(what: str) -> Callable[[str], str]:
    return lambda v: "" if v else f"empty; give {what}"


def _http_url_or_empty(value: str) -> str:
    from urllib.parse import urlsplit

    parts = urlsplit(value)
    if value and (parts.scheme not in ("http", "https") or not parts.hostname):
        return f"{value[:200]!r} is not an http(s) URL with a host (or '' for none)"
    return ""


PLANNER = (
    Param("network", "", "routing network file (.yaml, .geojson, .graphml), e.g. config/networks/singapore.yaml",
          check=_nonempty("a network file, e.g. config/networks/singapore.yaml")),
    Param("policy", "mwis", "planning policy: conflict graph + MWIS, the shortest-FIFO baseline, or "
          "first-fit (arrival order, the first conflict-free of the same k candidates)",
          choices=("mwis", "fifo", "firstfit")),
    Param("backend", "exact", "MWIS backend asked of the solver service (`ros2 run uam_solvers backends` lists "
          "them); takes effect at the next epoch", read_only=False, rule="backend_name"),
    Param("time_limit_s", 5.0, "MWIS solve time limit [s]; takes effect at the next epoch", 0.001, 3600.0,
          read_only=False),
    Param("seed", 0, "seed of stochastic MWIS backends (run_fleet.sh passes the run's --seed)", 0, INT32_MAX,
          read_only=False),
    Param("separation_m", D.SEPARATION_M, "separation minimum [m]: the sphere's radius, or the cylinder's horizontal minimum H",
          0.001, 100000.0),
    Param("separation_model", "", "loss of separation: 'sphere' (the paper's: 3D distance < separation_m) or "
          "'cylinder' (horizontal distance < separation_m while vertical distance < vertical_separation_m); "
          "'' = the network's own: the cylinder for a layered network (its levels are closer than the sphere), "
          "else the sphere; a choice that contradicts the network's is warned of at start",
          choices=("", "sphere", "cylinder")),
    Param("vertical_separation_m", D.VERTICAL_SEPARATION_M, "the cylinder's vertical minimum V [m] (unused by the sphere)", 0.001, 10000.0),
    Param("departure_slot_s", D.DEPARTURE_SLOT_S, "departure slots [s]: a request may depart at max(t, earliest) + i * slot up to "
          "min(t + epoch, latest); 0 = the paper's rule (depart at the epoch time t)", 0.0, 86400.0),
    Param("climb_rate_mps", D.CLIMB_RATE_MPS, "vertical climb rate at the vertiports of a layered network [m/s]", 0.001, 100.0),
    Param("descent_rate_mps", D.DESCENT_RATE_MPS, "vertical descent rate at the vertiports of a layered network [m/s]", 0.001, 100.0),
    Param("objective", "paper", "what the MWIS maximises: a registered objective (uam_planner.objectives; "
          "`python -m uam_planner.objectives` lists them, docs/objectives.md explains the built-in ones: "
          "'paper' (the paper's weights), 'count', 'delay', 'priority', 'fair')", rule="objective_name"),
    Param("baseline_order", "arrival", "order in which the fifo and firstfit policies serve requests: 'arrival' "
          "(the paper's) or 'priority' (priority class, then earliest latest departure, then arrival)",
          choices=("arrival", "priority")),
    Param("horizon_epochs", 1, "rolling planning horizon H of the mwis policy: the departures of the next H "
          "epochs are planned in one MWIS and only what departs in this epoch is committed, the rest planned "
          "again; 1 = the paper's one-epoch planning", 1, 100),
    Param("fair_window_s", 0.0, "objective 'fair': the operators' approval shares count only the decisions "
          "of the epochs in the last fair_window_s seconds (a sliding window of the run); 0 = the whole run",
          0.0, 1.0e7),
    Param("commit_ahead", False, "with horizon_epochs > 1, commit every selected departure of the horizon at "
          "once as a reservation (an approved flight never re-optimised; only a constraint's re-planning may "
          "revoke it) instead of planning the later epochs again"),
    Param("replan_policy", "", "how the flights a constraint update affects are re-planned "
          "(docs/replanning.md): 'mwis' (one MWIS over every affected flight's alternatives, solved like "
          "the epoch's), 'firstfit' (approval order, each one's first alternative that keeps separation); "
          "'' = the planning policy's own (mwis for mwis, firstfit for fifo and firstfit)",
          choices=("", "mwis", "firstfit")),
    Param("k", D.K, "candidate routes per request", 1, 100),
    Param("penalty_factor", D.PENALTY_FACTOR, "penalised Dijkstra factor for diverse candidates", 0.0, 1000.0),
    Param("speed_mps", D.SPEED_MPS, "cruise speed [m/s]", 0.001, 1000.0),
    Param("precompute_routes", True, "compute every aerodrome pair's candidate routes at start-up (1-2 s for "
          "Singapore) instead of on first use; same routes"),
    Param("solver_timeout_margin_s", 5.0, "extra wall time [s] to wait for the solver service before the local "
          "greedy fallback", 0.0, 3600.0, read_only=False),
    Param("solver_startup_timeout_s", 30.0, "wall time [s] to wait at start-up for the solver service before "
          "offering uam/plan_epoch (nodes start in any order); later a missing service means the local greedy "
          "fallback at once", 0.0, 3600.0),
    Param("use_solver_service", True, "call uam/solve_mwis; false solves in-process with the same backend"),
    Param("request_wait_timeout_s", 60.0, "wall time [s] an epoch waits for the requests the demand source "
          "released for it (named in the epoch call) before planning without the missing ones", 0.0, 3600.0,
          read_only=False),
    Param("max_pending", 5000, "requests waiting for a decision, all operators together; more are refused "
          "with the reason", 1, 10_000_000),
    Param("max_pending_new_operators", 2500, "requests waiting for a decision of operators first accepted since "
          "the last epoch, together: the operators that came before keep the rest of max_pending (a flood of new "
          "operator ids cannot push them out)", 1, 10_000_000),
    Param("max_pending_per_operator", 500, "requests waiting for a decision per operator_id; more are "
          "refused with the reason", 1, 10_000_000),
    Param("max_window_s", 3600.0, "latest_departure may be at most this far after the current simulation "
          "time [s]; later windows are refused", 0.0, 1e7),
    Param("max_request_lead_s", 60.0, "request_time may be at most this far after the current simulation "
          "time [s] (a request from the future)", 0.0, 1e7),
    Param("journal", "", "file where the planner journals its approvals (uam_bringup.journal), so a restarted "
          "planner checks the simulator's claim of the flights in the air against its own record; '' for none "
          "(run_fleet.sh writes <out>/planner-journal.jsonl)"),
    Param("priority_grants", "", "the priority classes each operator may ask for (uam_planner.grants: a YAML "
          "file with default and operators); a request above its grant is refused naming it; '' = every class "
          "taken (run_fleet.sh writes <out>/priority_grants.yaml: the generator's class, 0 for any other "
          "operator)"),
    Param("authorities_file", "", "the airspace authorities whose signed updates on uam/update_constraint "
          "are taken (uam_planner.authority: ids and public keys; run_fleet.sh writes <out>/authority/"
          "authorities.yaml); '' = live constraint updates are refused"),
    Param("constraints_file", "", "airspace constraints to plan around from the first epoch: a GeoJSON "
          "FeatureCollection or an ED-269 UAS zone file (docs/constraints.md); no candidate entering one "
          "during its window is approved; '' for none (the paper's airspace)"),
    Param("spatial_buffer_m", 0.0, "planning buffer added to the separation the planner keeps [m] ("
          "docs/disturbances.md; the audits keep the true minimum); 0 = none (the paper's)", 0.0, 100000.0),
    Param("temporal_buffer_s", 0.0, "temporal planning buffer [s]: plans keep the minimum plus the spatial "
          "buffer between any two times this far apart (the separation widened by v_max x it; "
          "docs/disturbances.md); 0 = none (the paper's)", 0.0, 3600.0),
    Param("reaction", False, "react to nonconforming flights (uam_planner.nonconformance): each "
          "report on uam/conformance is checked against the planner's own plan and the fleet state it saw, "
          "and a confirmed one gets the flight's intent updated from where it is, deconflicted; false = "
          "reports ignored (the paper's)"),
    Param("reaction_lateral_m", 30.0, "the planner's lateral conformance bound when it checks a report [m] "
          "(the conformance monitor's lateral_m)", 0.001, 100000.0),
    Param("reaction_vertical_m", 15.0, "the planner's vertical conformance bound [m] (the monitor's vertical_m)",
          0.001, 10000.0),
    Param("reaction_time_s", 10.0, "the planner's time conformance bound [s] (the monitor's time_s)",
          0.001, 86400.0),
    Param("conflict_probe_s", 0.0, "with the reaction on: the conflict probe's look-ahead [s]; at each "
          "reaction the airborne flights whose rest of plan, flown from where the planner last saw them at "
          "their observed speed, loses the minimum within it are updated too (docs/disturbances.md); 0 = "
          "no probe", 0.0, 3600.0),
    Param("conflict_probe_margin_m", 0.0, "with the conflict probe on: its margin [m]; it predicts losses "
          "of the minimum widened by this much and deconflicts its own updates with at least that (a "
          "tactical buffer between the flights predicted to come close; docs/disturbances.md); 0 = the "
          "true minimum", 0.0, 10000.0),
    Param("intent_volume_piece_s", 0.0, "F3548 mode: the longest time window of one published Volume4D [s] "
          "(the USS's volume_piece_s); > 0 keeps the published volumes of every two flights disjoint too, "
          "beside the separation (docs/f3548.md); 0 = the separation only", 0.0, 86400.0),
)

SOLVER = (
    Param("default_backend", "auto", "MWIS backend used when a request names none", read_only=False,
          rule="backend_available"),
    Param("default_time_limit_s", 10.0, "solve time limit [s] used when a request gives 0; at most "
          "max_time_limit_s", 0.001, 3600.0, read_only=False),
    # Every solve holds a worker process for up to its limit: an unbounded limit (1e9 s was
    # accepted) would let one request hold its lane for good.
    Param("max_time_limit_s", 60.0, "requests asking a longer time limit [s] are refused", 0.01, 3600.0,
          read_only=False),
    # A lower bound that serves every planner graph of the paper's scenarios (hundreds of vertices):
    # a tiny value would refuse every epoch and push the planner to its greedy fallback.
    Param("max_vertices", 20000, "graphs with more vertices are refused", 1000, 10_000_000, read_only=False),
    Param("layers", True, "split into components and apply exact reductions around the backend",
          read_only=False),
)

SIMULATOR = (
    Param("step_s", 1.0, "simulation step [s]", 0.001, 3600.0),
    # above 0: a run of 0 s plans nothing and records an empty run
    Param("duration_s", 3500.0, "simulated time after which the run ends [s]; epochs at t < duration_s",
          0.001, 1e7),
    Param("epoch_s", D.EPOCH_S, "time between planning epochs [s], a multiple of step_s; the one place the epoch "
          "length is configured (the planner gets it in each epoch call)", 0.001, 86400.0),
    Param("mode", "lockstep", "'lockstep': as fast as the planner allows, result independent of CPU speed; "
          "'realtime': paced at real_time_factor", choices=("lockstep", "realtime")),
    Param("real_time_factor", 1.0, "in realtime mode: simulated seconds per wall second", 0.001, 1e5,
          read_only=False),
    Param("use_demand_service", True, "at each epoch, ask the request generator (uam/release_demand) to "
          "publish the epoch's requests and pass their ids to the planner; false: requests come only "
          "from outside, as they arrive"),
    Param("wait_for_subscribers", [""], "start only once these nodes (by name) subscribe to "
          "uam/fleet_state, so a recording starts at t = 0 (config/simulator.yaml: [recorder]); [''] for none"),
    Param("startup_timeout_s", 300.0, "wall time [s] to wait at start for the planner's and the demand source's "
          "services (exactly one of each) and the subscribers named in wait_for_subscribers before ending the run "
          "with an error", 0.1, 86400.0),
    Param("progress_epochs", 10, "log a progress line (simulation time, approvals, airborne, wall time) every "
          "this many epochs, which run_fleet.sh shows on the terminal; 0 = none", 0, 1_000_000),
    Param("ack_timeout_s", 120.0, "wall time [s] to wait for an epoch's outcome before ending the run with "
          "an error",
          0.1, 86400.0),
    Param("reaction_period_s", 0.0, "with the planner's reaction on (its parameter reaction): the simulator "
          "also asks the planner to react every this many seconds between epochs, in lockstep, and flies "
          "the updates from that instant (the runner's reaction_period_s, docs/disturbances.md); 0 = at "
          "epochs only; otherwise less than epoch_s", 0.0, 86400.0),
    # disturbances (uam_sim.world.disturbance, docs/disturbances.md): all 0 = plans flown exactly
    Param("wind_speed_mps", 0.0, "steady wind speed [m/s]; 0 with the other levels 0 = plans flown exactly "
          "(the paper's)", 0.0, 100.0),
    Param("wind_from_deg", 270.0, "direction the steady wind blows from [deg clockwise from north]", 0.0, 360.0),
    Param("gust_std_mps", 0.0, "standard deviation of each horizontal gust component [m/s]", 0.0, 100.0),
    Param("gust_length_m", 2000.0, "typical gust wavelength [m]", 1.0, 1e6),
    Param("gust_period_s", 60.0, "typical gust period [s]", 0.1, 1e6),
    Param("speed_error", 0.0, "per-flight airspeed error bound: (1 + e) x the plan's speed, e uniform in "
          "[-speed_error, speed_error] (0.1 = 10 %)", 0.0, D.SPEED_ERROR_MAX),
    Param("delay_mean_s", 0.0, "mean departure delay [s] (exponential); 0 = on time", 0.0, 3600.0),
    Param("delay_max_s", 120.0, "departure delays are truncated here [s]", 0.0, 86400.0),
    Param("track_gain_per_s", 0.1, "cross-track guidance gain of the path-following model [1/s]", 0.001, 100.0),
    Param("max_lateral_m", 50.0, "bound of the cross-track offset of the path-following model [m]", 0.001, 10000.0),
    Param("compensate_steady_wind", True, "the aircraft crabs against the steady wind (false: it drifts)"),
    Param("disturbance_seed", 0, "seed of the wind field and of every flight's draws (run_fleet.sh passes "
          "the run's --seed)", 0, INT32_MAX),
    Param("vertical_gust_std_mps", 0.0, "standard deviation of the vertical gust [m/s]; 0 = none", 0.0, 100.0),
    Param("altitude_error_m", 0.0, "per-flight altitude-hold error bound: the height held above the plan is "
          "uniform in [-altitude_error_m, altitude_error_m] [m]; 0 = none", 0.0, 10000.0),
    Param("altitude_gain_per_s", 0.1, "altitude-hold gain of the path-following model [1/s]", 0.001, 100.0),
    Param("max_vertical_m", 30.0, "bound of the height offset of the path-following model [m]", 0.001, 10000.0),
)

REQUEST_GENERATOR = (
    Param("network", "", "routing network file; its aerodromes are the origins and destinations",
          check=_nonempty("a network file, e.g. config/networks/singapore.yaml")),
    Param("rate", 10.0, "requests per interval (paper: 1 to 20 per 30 s); fractional rates allowed", 0.0, 10000.0),
    Param("interval_s", 30.0, "time between request batches [s] (demand instants; each is released at the "
          "first epoch at or after it)", 0.001, 86400.0),
    Param("window_s", D.WINDOW_S, "latest departure - earliest departure of each request [s]", 0.0, 86400.0),
    Param("seed", 0, "random seed of the request stream", 0, INT32_MAX),
    Param("demand_file", "", "optional YAML demand file to replay instead of random requests "
          "(docs/demand-format.md)"),
    Param("operator_id", "generator", "operator id the requests are published under (ids are unique per "
          "operator); a demand file's per-request operator replaces it", check=_id_rule),
    Param("priority_share", 0.0, "share of random requests of class priority_class (e.g. 0.05 medical flights), "
          "drawn from the seeded stream after the paper's numbers; 0 = none (the paper's)", 0.0, 1.0),
    Param("priority_class", 1, "priority class of those requests (FlightRequest.priority)", 1, 255),
    Param("lead_time_s", 0.0, "random requests are filed this long before their earliest departure [s] "
          "(for a planning horizon; the planner's max_window_s bounds it)", 0.0, 86400.0),
)

def _mcap_path_rule(value: str) -> str:
    return "" if value.endswith(".mcap") else f"{value!r} must end with .mcap"


def _utc_rule(value: str) -> str:
    from uam_contract.stamps import scenario_start_ns

    try:
        scenario_start_ns(value)
    except ValueError as exc:
        return str(exc).split(": ", 1)[-1]
    return ""


def _run_choices_rule(value: str) -> str:
    """'' or a JSON object of names to numbers, strings or booleans."""
    if not value:
        return ""
    import json

    try:
        doc = json.loads(value)
    except json.JSONDecodeError as exc:
        return f"is not JSON ({exc})"
    if not isinstance(doc, dict) or not all(isinstance(v, (int, float, str, bool)) for v in doc.values()):
        return "must be a JSON object of names to numbers, strings or booleans"
    return ""


def _recorded_topics_rule(value) -> str:
    from uam_contract.names import RECORDED_TOPICS

    unknown = [t for t in value if t and t not in RECORDED_TOPICS]
    return f"{unknown!r} are not recorded topics; known: {', '.join(RECORDED_TOPICS)}" if unknown else ""


RECORDER = (
    Param("output", "run.mcap", "the .mcap file to write (parent directories are created; replaced if it exists)",
          check=_mcap_path_rule),
    Param("rerun", "off", "Rerun logging: 'off', 'save' (an .rrd file), 'spawn' (start a viewer) or 'connect' "
          "(stream to a running viewer at rerun_url)", choices=RERUN_MODES),
    Param("rerun_rrd", "", "the .rrd file for rerun:=save; empty = the output path with .rrd"),
    Param("rerun_url", "", "viewer gRPC url for rerun:=connect; empty = Rerun's default"),
    Param("network", "", "network file (config/networks/*.yaml) drawn in Rerun and the views; empty = none"),
    Param("compression", "zstd", "MCAP chunk compression", choices=("zstd", "lz4", "none")),
    Param("chunk_size_bytes", 256 * 1024, "uncompressed size after which an MCAP chunk is finished [bytes]",
          1024, 1 << 30),
    Param("flush_period_s", 1.0, "wall time after which the open chunk is written out, the most a crash "
          "loses [s]", 0.01, 3600.0),
    Param("finish_quiet_s", 0.5, "after the simulator's end of run, close once no message has arrived for this "
          "long (messages of other topics may still be on their way) and, after a clean end, the end's fleet "
          "state and every epoch's report are in [s wall]", 0.0, 60.0),
    Param("finish_timeout_s", 10.0, "after the simulator's end of run, close at the latest after this long "
          "[s wall]", 0.0, 3600.0),
    Param("views", True, "also write the run in standard types for generic viewers (/uam/view/*: PointCloud2, "
          "NavSatFix, MarkerArray; docs/views.md)"),
    Param("scenario_start_utc", SIM_CLOCK, "'sim': the view topics' header stamps in simulation time, the "
          "clock of every other topic; or an ISO 8601 instant of simulation time 0 (e.g. "
          f"{DEFAULT_SCENARIO_START_UTC}): their stamps are then that plus the simulation time, real UTC "
          "(log times: log_time_start_utc)", check=_utc_rule),
    Param("log_time_start_utc", DEFAULT_SCENARIO_START_UTC, "the scenario's UTC instant of simulation time 0: "
          "every message's MCAP log and publish time is that plus its simulation time, so Rerun and Foxglove "
          "show real dates (the analysis subtracts it again: MCAP record uam_clock); 'sim' = log times in "
          "simulation time (from 1970-01-01, as before)", check=_utc_rule),
    Param("view_fix_period_s", 5.0, "NavSatFix per vehicle every this many simulated seconds; 0 = every "
          "step [s]", 0.0, 3600.0),
    Param("foxglove_port", 0, "serve a live Foxglove WebSocket view on this port (0 = off; 8765 is "
          "Foxglove's default)", 0, 65535),
    # the airspace the run is planned in (run_fleet.sh passes the planner's values), written to the
    # MCAP's uam_airspace metadata so that the analysis audits in the run's model
    Param("separation_model", "", "the run's separation model (as the planner's; '' = the network's own, "
          "as the planner resolves it)", choices=("", "sphere", "cylinder")),
    Param("separation_m", D.SEPARATION_M, "the run's separation minimum (cylinder: H) [m]", 0.001, 100000.0),
    Param("vertical_separation_m", D.VERTICAL_SEPARATION_M, "the run's vertical minimum V of the cylinder [m]", 0.001, 10000.0),
    Param("departure_slot_s", D.DEPARTURE_SLOT_S, "the run's departure slot [s] (0 = the paper's rule)", 0.0, 86400.0),
    Param("run_choices", "", "the run's planning and flight choices as the launcher started the nodes with them, a "
          "JSON object (objective, priority share, horizon, lead time, buffers, reaction, probe, disturbances), "
          "written to the MCAP's uam_run metadata for the analysis' header; '' = none", check=_run_choices_rule),
    Param("wait_for_publishers", [""], "subscribe to the simulator's topics (/clock, uam/fleet_state, "
          "uam/fleet_poses) only once each of these recorded topics has a matched publisher: the simulator "
          "starts when the recorder subscribes to the fleet state, so the run then starts only when the "
          "recorder hears the planner and the demand source (run_fleet.sh: uam/flight_plans, "
          "uam/planning_reports, uam/requests, uam/epoch_sync); [''] = subscribe to everything at once",
          check=_recorded_topics_rule),
)

REPLAY = (
    Param("recording", "", "the .mcap file to replay (the command line's first argument sets it too)"),
    Param("rate", 1.0, "playback speed: 1 = original timing, 10 = ten times faster, 0 = as fast as possible",
          0.0, 1e9),
    Param("start_delay_s", 1.0, "wall time to wait after creating the publishers before the first message "
          "(lets subscribers discover them) [s]", 0.0, 3600.0),
    Param("wait_for_subscribers", 0, "start only once every replayed topic has at least this many subscribers "
          "(and start_delay_s has passed); 0 = do not wait", 0, 1000),
    Param("topics", [""], "topics to replay; [''] = every recorded topic"),
    Param("exit_when_done", True, "stop the node once everything is published"),
)

CONFORMANCE_MONITOR = (
    Param("lateral_m", 30.0, "lateral bound: horizontal distance from the nearest point of the planned path [m] "
          "(uam_sim.world.conformance, docs/disturbances.md)", 0.001, 100000.0),
    Param("vertical_m", 15.0, "vertical bound: height above or below that point [m]", 0.001, 10000.0),
    Param("time_s", 10.0, "time bound: |now - the planned time of that point| [s]", 0.001, 86400.0),
)

# the F3548 USS-USS interface (docs/f3548.md; run_fleet.sh --uss-port)
USS = (
    Param("port", 8090, "TCP port of the HTTP server (0 = any free port, logged)", 0, 65535),
    Param("journal", "", "the planner's journal (its own record of approvals, versions and constraint sets, "
          "uam_bringup.journal): served instead of what anyone can publish on uam/flight_plans and "
          "uam/constraints, with the clock of the simulator it names (its fleet states); '' = the topics "
          "(warned at start; run_fleet.sh gives <out>/planner-journal.jsonl)"),
    Param("authority_key", "", "the private key (PEM) of the USS's own airspace authority, with which it passes "
          "peers' intents and constraints to the planner (signed uam/update_constraint updates; "
          "uam_planner.authority); '' = peers' changes are only logged (run_fleet.sh makes one, 'uss-peers', "
          "not an admin)"),
    Param("authority_id", "uss-peers", "that authority's id, as in the planner's authorities file"),
    Param("flight_planning_timeout_s", 25.0, "with authority_key: InterUSS's flight_planning interface is served, "
          "each flight plan put to the planner (signed uam/uss_flight_plan requests of operator flight_planning, which "
          "the authorities file gives that authority); the longest wall time [s] an answer waits for the planner's "
          "decision (then Failed, the request withdrawn); below the test director's read timeout", 0.1, 3600.0),
    Param("peers", [""], "the managers (token subjects) whose notifications of intents and constraints this USS "
          "takes; [''] = any caller with a valid token and scope. Whoever calls, a notification must name its "
          "caller as the manager, and an entity held changes only by its manager (uam_sim.f3548.peers)"),
    Param("max_clock_step_s", 60.0, "with journal: the most the served clock may advance from one fleet state "
          "of the simulator to the next [s] (a forged jump is refused)", 0.001, 1e6),
    Param("host", "127.0.0.1", "address to bind ('0.0.0.0' for every interface; loopback by default)",
          check=_nonempty("host")),
    Param("auth", "verify", "'verify': every request needs a bearer access token signed by the auth server "
          "(auth_key), unexpired, for this USS (auth_audience) and with the endpoint's F3548 scope; 'off': no "
          "token asked for (local runs only; announced at start)", choices=("verify", "off")),
    Param("auth_key", "", "the auth server's public key: a PEM public key or a JWK / JWKS file (needed by "
          "'verify'; `python -m uam_sim.uss_server keys DIR` makes a development pair)"),
    Param("auth_audience", "", "comma-separated audiences a token's aud may name; '' = the host of uss_base_url "
          "(loopback: localhost and 127.0.0.1)"),
    Param("workers", 8, "threads serving requests (a bounded pool; idle connections hold none)", 1, 256),
    Param("max_connections", 256, "connections waiting or in service at most (at the bound the oldest silent one "
          "is closed; none silent: 503); at least workers", 1, 10000),
    Param("uss_base_url", "", "the base URL the intents name (no trailing '/'); '' = http://<host>:<port> of the server as bound"),
    Param("network", "", "network file (its origin places the volumes on WGS84)"),
    Param("scenario_start_utc", DEFAULT_SCENARIO_START_UTC, "the UTC instant of simulation time 0 (F3548 "
          "times are absolute)", check=_utc_rule),
    Param("separation_model", "", "the run's separation model ('' = the network's own)",
          choices=("", "sphere", "cylinder")),
    Param("separation_m", D.SEPARATION_M, "separation minimum (cylinder: H); volumes are buffered by half [m]",
          0.001, 100000.0),
    Param("vertical_separation_m", D.VERTICAL_SEPARATION_M, "the cylinder's vertical minimum V; volumes are buffered by "
          "half [m]", 0.001, 10000.0),
    Param("volume_piece_s", 5.0, "longest time window of one Volume4D [s] (docs/f3548.md: the bound)",
          0.01, 86400.0),
    Param("dss_url", "", "the DSS (the URL its /dss/v1 paths are under, e.g. http://localhost:8082) in which the USS "
          "keeps a reference of every intent it serves, whose OVN it then serves, and whose subscribers it notifies "
          "(uam_sim.f3548.dss_sync); '' = no DSS: local OVNs, no DSS called", check=_http_url_or_empty),
    Param("dss_token_file", "", "with dss_url, one of three token sources: a file holding one bearer token sent "
          "with every DSS call and notification (it needs every scope: utm.strategic_coordination, "
          "utm.constraint_processing; and an aud each receiver takes)"),
    Param("dss_dev_key", "", "with dss_url, one of three token sources: a development private key (PEM; "
          "`python -m uam_sim.uss_server keys DIR`) that mints a token per audience and scope, sub dss_subject"),
    Param("dss_auth_url", "", "with dss_url, one of three token sources: an auth server's token endpoint asked "
          "as InterUSS's dummy OAuth server is (GET ?grant_type=client_credentials&scope=..&intended_audience=.."
          "&sub=dss_subject), e.g. http://localhost:8085/token"),
    Param("dss_subject", "uam-fleet", "the sub of minted or asked tokens: this USS's identity at the DSS (its "
          "references' manager)", check=_nonempty("the USS's identity, e.g. uam-fleet")),
    Param("dss_audience", "", "the aud of tokens for the DSS; '' = the host of dss_url"),
    Param("dss_retry_s", 5.0, "wall time [s] between retries of the DSS puts and deletes that failed (each "
          "change is tried at once)", 0.05, 3600.0),
)

TABLES = {"planner": PLANNER, "solver": SOLVER, "simulator": SIMULATOR, "request_generator": REQUEST_GENERATOR,
          "recorder": RECORDER, "replay": REPLAY,
          "conformance_monitor": CONFORMANCE_MONITOR, "uss": USS}


def markdown() -> str:
    """The tables as Markdown (docs/parameters.md is this text)."""
    out = ["# Node parameters", "",
           "Generated by `python -m uam_contract.params` from `src/uam_contract/uam_contract/params.py`, the "
           "tables the nodes declare. *read-only*: read at start-up only; a change at run time is refused.",
           ""]
    for node, table in TABLES.items():
        out += [f"## {node}", "", "| parameter | default | changes at run time | meaning |", "|---|---|---|---|"]
        for p in table:
            out.append(f"| `{p.name}` | `{p.default!r}` | {'yes' if not p.read_only else 'read-only'} | "
                       f"{p.text().replace('|', '/')} |")
        out.append("")
    return "\n".join(out)


def main(argv=None) -> int:
    sys.stdout.write(markdown())
    return 0


if __name__ == "__main__":
    sys.exit(main())
