"""Request generator node: publishes flight requests on /uam/requests.

    ros2 run uam_sim request_generator --ros-args --params-file config/request_generator.yaml

Every interval (30 s of simulation time) it publishes `rate` requests between random distinct
aerodromes of the network (seeded; earliest departure now, latest now + window_s), or, when
`demand_file` is set, replays that file (format: docs/demand-format.md). It is driven by the
simulator's epoch announcements on /uam/epoch_sync and acknowledges each epoch with the number of
requests published so far, so the planner knows when it has them all (lockstep). The stream is
uam_sim.demand's, identical to the in-process experiment runner's for the same seed.
"""

from __future__ import annotations

import math
import sys
from functools import partial

from rclpy.node import Node
from rclpy.parameter import Parameter
from uam_msgs.msg import EpochSync, FlightRequest

from uam_planner.network import load_network
from uam_bringup import contract as c
from uam_bringup import conversions as m
from uam_bringup import qos
from uam_bringup.runtime import run_node
from uam_bringup.params import declare
from uam_sim.demand import DemandSchedule, RequestGenerator, load_demand


class RequestGeneratorNode(Node):
    def __init__(self, **kwargs):
        kwargs.setdefault("parameter_overrides", [])
        if not any(p.name == "use_sim_time" for p in kwargs["parameter_overrides"]):
            kwargs["parameter_overrides"].append(Parameter("use_sim_time", Parameter.Type.BOOL, True))
        super().__init__("request_generator", **kwargs)
        d = partial(declare, self)
        net_path = d("network", "", "routing network file; its aerodromes are the origins and destinations")
        rate = d("rate", 10.0, "requests per interval (paper: 1 to 20 per 30 s); fractional rates allowed", 0.0, 10000.0)
        interval = d("interval_s", 30.0, "time between request batches [s]; must match the simulator's epoch_s", 0.001, 86400.0)
        window = d("window_s", 60.0, "latest departure - earliest departure of each request [s]", 0.0, 86400.0)
        seed = d("seed", 0, "random seed of the request stream", 0, 2**31 - 1)
        demand_file = d("demand_file", "", "optional YAML demand file to replay instead of random requests (docs/demand-format.md)")
        if not net_path:
            raise ValueError("parameter network: empty; give a network file, e.g. config/networks/singapore.yaml")
        network = load_network(net_path)
        if demand_file:
            self.source = DemandSchedule(load_demand(demand_file, network.aerodrome_ids, window), interval)
        else:
            self.source = RequestGenerator(network.aerodrome_ids, rate, interval, window, seed)
        self.interval_s = interval
        self._pub = self.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_LATCHED)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED)
        self._done_epochs: set[int] = set()
        self.published = 0
        self.finished = False
        self.get_logger().info(
            "replaying " + demand_file if demand_file else
            f"random demand: {rate:g} requests per {interval:g} s, seed {seed}, "
            f"{len(network.aerodrome_ids)} aerodromes")

    def _on_sync(self, msg: EpochSync) -> None:
        if msg.sender != "simulator":
            return
        if msg.finished:
            self.finished = True
            return
        k = int(msg.epoch_index)
        if k in self._done_epochs:
            return
        self._done_epochs.add(k)
        t_s = m.from_time(msg.epoch_time)
        interval_index = t_s / self.interval_s
        if math.isclose(interval_index, round(interval_index), abs_tol=1e-9):
            for req in self.source.requests_at(t_s, int(round(interval_index))):
                self._pub.publish(m.request_to_msg(req))
                self.published += 1
        self._sync_pub.publish(EpochSync(epoch_index=k, epoch_time=msg.epoch_time, sender="request_generator",
                                         requests_published=self.published))


def main(args=None) -> int:
    return run_node(RequestGeneratorNode, "request_generator", args)


if __name__ == "__main__":
    sys.exit(main())
