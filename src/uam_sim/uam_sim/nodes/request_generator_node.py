"""Request generator node: the demand source; publishes flight requests on uam/requests.

    ros2 run uam_sim request_generator --ros-args --params-file config/request_generator.yaml

Every interval (30 s of simulation time) it has `rate` requests between random distinct
aerodromes of the network (seeded; earliest departure then, latest then + window_s), or, when
`demand_file` is set, the entries of that file (format: docs/demand-format.md). It publishes
them when the simulator asks (service uam/release_demand at each epoch: every demand instant at
or before the epoch time not yet released) and answers with their ids, which the simulator hands
to the planner: the planner waits for those requests, not for a count. The requests carry
``operator_id`` (parameter, default "generator"). The stream is uam_sim.demand's, identical to
the in-process experiment runner's for the same seed. Parameters:
uam_bringup.params.REQUEST_GENERATOR (docs/parameters.md).
"""

from __future__ import annotations

import sys

from rclpy.node import Node
from uam_msgs.msg import EpochSync, FlightRequest
from uam_msgs.srv import ReleaseDemand

from uam_bringup import contract as c
from uam_bringup import conversions as m
from uam_bringup import qos, wire
from uam_bringup.params import REQUEST_GENERATOR, declare_table
from uam_bringup.runtime import run_node
from uam_planner.network import load_network
from uam_sim.demand import DemandSchedule, RequestGenerator, load_demand


class RequestGeneratorNode(Node):
    def __init__(self, **kwargs):
        # No use_sim_time: the node takes simulation time from the epoch protocol, never from a
        # clock, and a /clock subscription would cost it a callback per simulated second (about
        # 3 CPU s of a paper run; BENCHMARKS.md).
        super().__init__("request_generator", **kwargs)
        p = declare_table(self, REQUEST_GENERATOR)
        network = load_network(p["network"])
        if p["demand_file"]:
            self.source = DemandSchedule(load_demand(p["demand_file"], network.aerodrome_ids, p["window_s"]),
                                         p["interval_s"])
        else:
            self.source = RequestGenerator(network.aerodrome_ids, p["rate"], p["interval_s"], p["window_s"], p["seed"])
        self.interval_s = p["interval_s"]
        self.operator_id = p["operator_id"]
        self._pub = self.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_REQUESTS)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED)
        self.create_service(ReleaseDemand, c.SERVICE_RELEASE_DEMAND, self._on_release)
        self._next_instant = 0
        self._released: dict[int, list[str]] = {}  # epoch -> ids released for it (a repeated call gets them again)
        self.published = 0
        self.finished = False
        self.get_logger().info(
            "replaying " + p["demand_file"] if p["demand_file"] else
            f"random demand: {p['rate']:g} requests per {p['interval_s']:g} s, seed {p['seed']}, "
            f"{len(network.aerodrome_ids)} aerodromes, operator {self.operator_id!r}")

    def _on_release(self, request: ReleaseDemand.Request, response: ReleaseDemand.Response):
        k = int(request.epoch_index)
        if k not in self._released:
            t_s = m.from_time(request.epoch_time)
            ids = []
            # every demand instant up to t, in time order (as uam_sim.experiment.run_scenario)
            while self._next_instant * self.interval_s <= t_s + 1e-9:
                i = self._next_instant
                for req in self.source.requests_at(i * self.interval_s, i):
                    self._pub.publish(m.request_to_msg(req, operator_id=self.operator_id))
                    ids.append(wire.scoped_id(self.operator_id, req.request_id))
                    self.published += 1
                self._next_instant += 1
            self._released[k] = ids
            self._sync_pub.publish(EpochSync(epoch_index=k, epoch_time=request.epoch_time, sender="request_generator",
                                             requests_published=self.published))
        response.request_ids = self._released[k]
        return response

    def _on_sync(self, msg: EpochSync) -> None:
        if msg.sender == "simulator" and msg.finished:
            self.finished = True


def main(args=None) -> int:
    return run_node(RequestGeneratorNode, "request_generator", args, events_executor=True)


if __name__ == "__main__":
    sys.exit(main())
