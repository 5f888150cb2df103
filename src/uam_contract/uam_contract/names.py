"""The ROS contract of the UAM node graph: topic and service names, QoS, frame and wire limits.

rclpy-free (QoS as :class:`uam_contract.qos_spec.QosSpec`, turned into rclpy profiles by
:mod:`uam_bringup.qos`), so the analysis of a recording and the tests can read it without ROS.

Names are *relative*: a node started in a namespace (``--ros-args -r __ns:=/fleet2``) or a
launch file's ``PushRosNamespace`` moves the whole graph, and a remapping of ``uam/requests``
moves that one topic for every node. In the default namespace they resolve to ``/uam/...``,
the names recordings carry. ``/clock`` stays absolute: rclpy's time source listens there.
"""

from __future__ import annotations

from uam_contract.qos_spec import QosSpec

FRAME_ID = "enu"

# ---- topics and services (relative) -------------------------------------------------------------
TOPIC_REQUESTS = "uam/requests"
TOPIC_PLANS = "uam/flight_plans"
TOPIC_REPORTS = "uam/planning_reports"
TOPIC_FLEET = "uam/fleet_state"
TOPIC_POSES = "uam/fleet_poses"
TOPIC_SYNC = "uam/epoch_sync"
TOPIC_CONFORMANCE = "uam/conformance"   # the conformance monitor's output
TOPIC_CLOCK = "/clock"
SERVICE_SOLVE = "uam/solve_mwis"
SERVICE_PLAN_EPOCH = "uam/plan_epoch"
SERVICE_RELEASE_DEMAND = "uam/release_demand"
# the simulator asks the planner to react between epochs (uam_msgs/srv/React)
SERVICE_REACT = "uam/react"
# live airspace constraints: the planner serves updates and publishes the set it plans with
SERVICE_UPDATE_CONSTRAINT = "uam/update_constraint"
# a USS's flight requests, signed by its airspace authority (uam_planner.signed_requests; the
# UpdateConstraint type): the planner answers each once decided
SERVICE_USS_FLIGHT_PLAN = "uam/uss_flight_plan"
TOPIC_CONSTRAINTS = "uam/constraints"
#: every parameter change a node accepted at run time, as JSON ({"node", "parameter", "value"}),
#: published by the node itself (uam_bringup.params.declare_table) and named in the summary
TOPIC_PARAMETER_CHANGES = "uam/parameter_changes"

# the standard-type views the recorder writes for generic viewers (uam_sim.views.std_msgs_export)
TOPIC_VIEW_NETWORK = "uam/view/network"
TOPIC_VIEW_ROUTES = "uam/view/routes"
TOPIC_VIEW_FLEET = "uam/view/fleet"
TOPIC_VIEW_FIX_PREFIX = "uam/view/fix/"
TOPIC_VIEW_NETWORK_POINTS = "uam/view/network_points"
TOPIC_VIEW_CONSTRAINTS = "uam/view/constraints"
TOPIC_VIEW_CONSTRAINT_POINTS = "uam/view/constraint_points"
# the live Foxglove WebSocket's channels (uam_sim.views.foxglove_live)
TOPIC_LIVE_NETWORK = "uam/live/network"
TOPIC_LIVE_ROUTES = "uam/live/routes"
TOPIC_LIVE_FLEET = "uam/live/fleet"
TOPIC_LIVE_FLEET_GEO = "uam/live/fleet_geo"
TOPIC_LIVE_METRICS = "uam/live/metrics"

#: the recorder's ``wait_for_publishers`` as run_fleet.sh and the launch file give it: the run
#: starts once the recorder hears the planner and the demand source
RECORDER_WAITS_FOR = (TOPIC_PLANS, TOPIC_REPORTS, TOPIC_REQUESTS, TOPIC_SYNC)

#: Rerun sinks of the recorder (uam_sim.views.rerun_log.RerunLogger)
RERUN_MODES = ("off", "save", "spawn", "connect")


def resolved(name: str, namespace: str = "/") -> str:
    """The absolute name ``name`` resolves to in ``namespace`` (no remapping), e.g. for recordings."""
    if name.startswith("/"):
        return name
    ns = namespace.rstrip("/")
    return f"{ns}/{name}"


# ---- QoS ----------------------------------------------------------------------------------------
# Nothing of the run may be lost, and a late subscriber (viewer, recorder) still gets every plan.
# (KEEP_LAST with a deep history rather than KEEP_ALL: a KEEP_ALL writer blocks when a reader lags.)
QOS_LATCHED = QosSpec(history="keep_last", depth=20000, reliability="reliable", durability="transient_local")
# High-rate streams (fleet state every step): reliable so recordings are complete.
QOS_STREAM = QosSpec(history="keep_last", depth=1000, reliability="reliable", durability="volatile")
# Like rclpy's ClockQoS but reliable and deep (a tick is 12 bytes: depth 100 lost ticks while a recorder at
# nice lagged behind the run), so recordings hold every tick; best-effort readers still match.
QOS_CLOCK = QosSpec(history="keep_last", depth=10000, reliability="reliable", durability="volatile")
# Recorder's reader of volatile streams: deep, so a busy recorder does not drop messages.
QOS_RECORD_VOLATILE = QosSpec(history="keep_last", depth=10000, reliability="reliable", durability="volatile")
# Requests from operators: transient local so a planner that starts (or restarts) late still gets
# every request; the planner's reader history bounds what a flood can queue.
QOS_REQUESTS = QOS_LATCHED
# The constraint set (a std_msgs/String of GeoJSON, the whole set each time it changes): latched, so a
# late subscriber gets the current set, and deep enough that a recorder that starts late still gets
# every set the run planned with (the audit of incursions needs each one).
QOS_CONSTRAINTS = QosSpec(history="keep_last", depth=1000, reliability="reliable", durability="transient_local")

#: topic -> (message type ``pkg/msg/Type``, QoS of the recorder's subscription). A transient-local
#: reader does not match a volatile writer, so each topic is read with its writers' durability.
RECORDED_TOPICS: dict[str, tuple[str, QosSpec]] = {
    TOPIC_CLOCK: ("rosgraph_msgs/msg/Clock", QOS_RECORD_VOLATILE),
    TOPIC_REQUESTS: ("uam_msgs/msg/FlightRequest", QOS_LATCHED),
    TOPIC_PLANS: ("uam_msgs/msg/FlightPlan", QOS_LATCHED),
    TOPIC_REPORTS: ("uam_msgs/msg/PlanningReport", QOS_LATCHED),
    TOPIC_FLEET: ("uam_msgs/msg/FleetState", QOS_RECORD_VOLATILE),
    TOPIC_POSES: ("geometry_msgs/msg/PoseArray", QOS_RECORD_VOLATILE),
    TOPIC_SYNC: ("uam_msgs/msg/EpochSync", QOS_LATCHED),
    TOPIC_CONSTRAINTS: ("std_msgs/msg/String", QOS_CONSTRAINTS),
    TOPIC_PARAMETER_CHANGES: ("std_msgs/msg/String", QOS_LATCHED),
    TOPIC_CONFORMANCE: ("uam_msgs/msg/Conformance", QOS_RECORD_VOLATILE),
}
