"""Short runs recorded in process, as the node graph's recorder would record them, for view tests.

The planner runs in process (``uam_sim.studies.experiment.run_scenario``); its decisions go to the
recording at their decision times, and the fleet flying the approved plans (``uam_sim.world.fleet``)
is sampled every simulated second into ``/uam/fleet_state`` with the simulator's CDR encoder.
With ``views=True`` the standard-message view topics (``uam_sim.views.std_msgs_export``) are added as
the recorder adds them. Needs the built workspace (uam_msgs).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

NS = 1_000_000_000
ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "config" / "networks" / "tiny.yaml"


def record_run(path, method: str = "greedy", network=None, rate: float = 4.0, seed: int = 0,
               duration_s: float = 240.0, views: bool = True, rerun_rrd=None, stop_s: float | None = None):
    """Record a short run into ``path`` (.mcap); optionally also log it to ``rerun_rrd`` (.rrd).

    ``stop_s``: last simulated second written (default: until every approved flight landed), so
    a recording can end with aircraft in the air. Returns (ScenarioResult, network).
    """
    from uam_msgs.msg import FleetState, FlightPlan, FlightRequest, PlanningReport
    from rclpy.serialization import serialize_message
    from uam_planner.network import load_network
    try:   # the ROS contract's conversions (uam_bringup), or where they lived before it
        from uam_planner.nodes import conversions as m
    except ImportError:
        from uam_planner.nodes import messages as m

    from uam_sim.recording.cdr import encode_fleet_state
    from uam_sim.studies.experiment import make_config, run_scenario
    from uam_sim.world.fleet import Fleet
    from uam_sim.recording import McapRecorder, deserialize, RecordedMessage
    from uam_sim.views.rerun_log import RerunLogger
    from uam_sim.views.std_msgs_export import FRAME_ID, ViewExporter

    net = network if network is not None else load_network(TINY)
    cfg = make_config({"network": str(TINY), "out": str(Path(path).parent / "res"), "include_qpu": False,
                       "tts": {"enabled": False}})
    events = []  # (t_ns, order, topic, cdr)
    policy = "fifo" if method == "fifo" else "mwis"
    flights = []

    def observer(t_s, epoch, submitted, refused, res):
        ns = int(round(t_s * NS))
        for r in submitted:
            events.append((ns, 0, "/uam/requests", serialize_message(m.request_to_msg(r))))
        for f in res.approved:
            plan = m.approved_plan(f, t_s, policy)
            events.append((ns, 1, "/uam/flight_plans", serialize_message(plan)))
            flights.append((ns, f.request_id, m.trajectory_from_plan(plan)))
        events.append((ns, 2, "/uam/planning_reports", serialize_message(m.report_to_msg(res.report))))

    result = run_scenario(net, method, rate, seed, duration_s, cfg, observer=observer)
    end_s = max([float(traj.times_s[-1]) for _, _, traj in flights] + [duration_s])
    last = int(np.ceil(end_s)) if stop_s is None else int(stop_s)
    fleet = Fleet()
    pending = sorted(flights, key=lambda x: x[0])
    for k in range(last + 1):
        while pending and pending[0][0] <= k * NS:
            _, rid, traj = pending.pop(0)
            fleet.add(rid, traj)
        s = fleet.sample(float(k))
        events.append((k * NS, 3, "/uam/fleet_state", encode_fleet_state(
            k, 0, FRAME_ID, k, s.vehicle_ids, s.positions_m, s.velocities_mps, s.phases,
            s.segment_indices, s.flown_m, s.remaining_m)))
    events.sort(key=lambda e: (e[0], e[1]))
    types = {"/uam/requests": FlightRequest, "/uam/flight_plans": FlightPlan,
             "/uam/planning_reports": PlanningReport, "/uam/fleet_state": FleetState}
    exporter = ViewExporter(net) if views else None
    logger = RerunLogger("save", rerun_rrd, network=net) if rerun_rrd else None
    with McapRecorder(path) as rec:
        for topic, cls in types.items():
            rec.add_topic(topic, cls)

        def put(vm):
            if vm.topic not in rec.topics:
                rec.add_topic(vm.topic, vm.type_name)
            rec.write(vm.topic, vm.data, vm.sim_time_ns)

        if exporter:
            for vm in exporter.network_messages(0):
                put(vm)
        for ns, _, topic, data in events:
            rec.write(topic, data, ns)
            if exporter is None and logger is None:
                continue
            msg = None
            if topic in ("/uam/fleet_state", "/uam/flight_plans", "/uam/planning_reports"):
                msg = deserialize(RecordedMessage(topic, rec.topics[topic], bytes(data), ns, ns))
            if exporter and topic == "/uam/fleet_state":
                for vm in exporter.fleet_state_messages(msg):
                    put(vm)
            elif exporter and topic == "/uam/flight_plans":
                for vm in exporter.plan_messages(msg):
                    put(vm)
            if logger:
                if topic == "/uam/fleet_state":
                    logger.log_fleet_state_msg(msg)
                elif topic == "/uam/flight_plans":
                    logger.log_flight_plan_msg(msg)
                elif topic == "/uam/planning_reports":
                    logger.log_planning_report_msg(msg)
    if logger:
        logger.close()
    return result, net
