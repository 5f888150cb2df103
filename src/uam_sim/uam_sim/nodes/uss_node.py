"""USS node: the planner's live plans and constraints served over F3548's USS-USS interface
(docs/f3548.md).

``install/uam_sim/lib/uam_sim/uss --ros-args -p port:=8090 -p network:=config/networks/tiny.yaml``
(``run_fleet.sh --uss-port 8090`` starts it with the run's network and separation model).

It subscribes to ``uam/flight_plans`` (every approved plan and every new version becomes or
replaces an operational intent; a cancellation ends it), ``uam/requests`` (each request's
priority, which a FlightPlan does not carry), ``uam/constraints`` (the set the planner plans
with) and ``/clock`` (states and volume clipping follow simulation time), and serves them with
:class:`uam_sim.f3548.uss_server.UssServer` (Flask on a bounded pool of worker threads; a bad
request is answered with the standard's error and never stops the node). Parameters:
``uam_contract.params.USS``. With ``auth`` ``verify`` (the default) the node does not start
without ``auth_key``; with ``off`` it logs a warning saying so when it starts.
"""

from __future__ import annotations

import sys
from dataclasses import replace

from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from uam_bringup import qos
from uam_bringup.params import declare_table
from uam_bringup.runtime import run_node
from uam_contract import names as c
from uam_contract.params import USS
from uam_contract.stamps import stamp_s
from uam_msgs.msg import FlightPlan, FlightRequest


class UssNode(Node):
    def __init__(self, **kwargs):
        super().__init__("uss", **kwargs)
        p = declare_table(self, USS)
        from uam_planner.f3548 import IntentContext, VolumeSpec
        from uam_planner.network import load_network
        from uam_planner.separation import SeparationModel
        from uam_sim.f3548.uss_server import IntentStore, UssServer

        if not p["network"]:
            raise ValueError("parameter network: a network file is needed (its origin places the volumes)")
        self.network = load_network(p["network"])
        kind = p["separation_model"] or self.network.separation_model
        model = SeparationModel(kind, p["separation_m"], p["vertical_separation_m"])
        spec = VolumeSpec.for_separation(model, p["volume_piece_s"])

        def context(port):
            return IntentContext(self.network.origin_lat_lon_alt, spec,
                                 scenario_start_utc=p["scenario_start_utc"],
                                 uss_base_url=p["uss_base_url"] or f"http://localhost:{port}")
        self.store = IntentStore(context(p["port"]))
        self._priority: dict[tuple, int] = {}
        self.server = UssServer(self.store, p["host"], p["port"], p["auth"], auth_key=p["auth_key"],
                                auth_audience=p["auth_audience"], workers=p["workers"],
                                max_connections=p["max_connections"])
        self.store.ctx = context(self.server.port)  # port 0: the port the server got (store empty)
        base = self.store.ctx.uss_base_url
        self.server.start()
        log = self.get_logger().warning if self.server.auth == "off" else self.get_logger().info
        log(f"{self.server.announcement}; base url {base}; {p['workers']} workers")
        self.create_subscription(FlightPlan, c.TOPIC_PLANS, self._on_plan, qos.QOS_LATCHED)
        self.create_subscription(FlightRequest, c.TOPIC_REQUESTS, self._on_request, qos.QOS_REQUESTS)
        self.create_subscription(String, c.TOPIC_CONSTRAINTS, self._on_constraints, qos.QOS_CONSTRAINTS)
        self.create_subscription(Clock, c.TOPIC_CLOCK, self._on_clock, qos.QOS_CLOCK)
        self.plans = 0

    def _on_request(self, msg) -> None:
        self._priority[(msg.operator_id, msg.request_id)] = int(getattr(msg, "priority", 0))

    def _on_plan(self, msg) -> None:
        from uam_planner.nodes.conversions import flight_from_plan
        if msg.outcome != FlightPlan.OUTCOME_APPROVED:
            if int(getattr(msg, "version", 0) or 0) > 1 or msg.state == FlightPlan.STATE_ENDED:
                self.store.end(msg.operator_id, msg.request_id)  # a cancellation of a version
            return
        try:
            f = flight_from_plan(msg)
        except ValueError as exc:
            self.get_logger().warning(f"plan {msg.operator_id}/{msg.request_id}: not served: {exc}")
            return
        f = replace(f, operator_id=msg.operator_id,
                    priority=self._priority.get((msg.operator_id, msg.request_id), 0))
        self.store.put_flight(f)
        self.plans += 1

    def _on_constraints(self, msg) -> None:
        from uam_planner.live_constraints import constraints_from_text
        try:
            _, pairs = constraints_from_text(msg.data, self.network)
        except ValueError as exc:
            self.get_logger().warning(f"{c.TOPIC_CONSTRAINTS}: not served: {exc}")
            return
        self.store.set_constraints([con for con, _ in pairs])

    def _on_clock(self, msg) -> None:
        self.store.set_time(stamp_s(msg.clock))

    def close(self) -> None:
        self.server.stop()


def main(args=None) -> int:
    return run_node(UssNode, "uss", sys.argv if args is None else args)


if __name__ == "__main__":
    sys.exit(main())
