"""Request generator node: the demand source; publishes flight requests on uam/requests.

    ros2 run uam_sim request_generator --ros-args --params-file config/request_generator.yaml

Every interval (30 s of simulation time) it has `rate` requests between random distinct
aerodromes of the network (seeded; earliest departure then, latest then + window_s), or, when
`demand_file` is set, the entries of that file (format: docs/demand-format.md). It publishes
them when the simulator asks (service uam/release_demand at each epoch: every demand instant at
or before the epoch time not yet released) and answers with their ids, which the simulator hands
to the planner: the planner waits for those requests, not for a count. The requests carry
``operator_id`` (parameter, default "generator"). The stream is uam_sim.world.demand's, identical to
the in-process experiment runner's for the same seed. Parameters:
uam_contract.params.REQUEST_GENERATOR (docs/parameters.md).
"""

from __future__ import annotations

import math
import secrets
import sys

from rclpy.node import Node
from uam_msgs.msg import EpochSync, FlightRequest
from uam_msgs.srv import ReleaseDemand

from uam_contract import names as c
from uam_planner.nodes import conversions as m
from uam_bringup import qos
from uam_contract import wire
from uam_bringup.params import declare_table
from uam_contract.params import REQUEST_GENERATOR
from uam_bringup.runtime import run_node
from uam_planner.network import load_network
from uam_sim.world.demand import DemandSchedule, RequestGenerator, load_demand


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
            self.source = RequestGenerator(network.aerodrome_ids, p["rate"], p["interval_s"], p["window_s"], p["seed"],
                                           priority_share=p["priority_share"], priority_class=p["priority_class"],
                                           lead_time_s=p["lead_time_s"])
        self.interval_s = p["interval_s"]
        self.operator_id = p["operator_id"]
        self._pub = self.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_REQUESTS)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED)
        self.create_service(ReleaseDemand, c.SERVICE_RELEASE_DEMAND, self._on_release)
        self._next_instant = 0
        self._released: dict[int, list[str]] = {}  # epoch -> ids released for it (a repeated call gets them again)
        # one partner (docs/security.md): the simulator of the first call; only its next epoch
        self.session = secrets.token_hex(8)
        self.bound_simulator: str | None = None
        self._epoch_s: float | None = None
        self.published = 0
        self.finished = False
        self.get_logger().info(
            "replaying " + p["demand_file"] if p["demand_file"] else
            f"random demand: {p['rate']:g} requests per {p['interval_s']:g} s, seed {p['seed']}, "
            f"{len(network.aerodrome_ids)} aerodromes, operator {self.operator_id!r}")

    def _check_release(self, request: ReleaseDemand.Request) -> str:
        """Why this call is not the bound simulator's next epoch (or a repeat of its last), or ''."""
        session, k = request.session, int(request.epoch_index)
        if not session or len(session) > wire.MAX_ID_LENGTH:
            return f"session: {wire.echo(session)} must be the simulator's run token"
        if self.bound_simulator is not None and session != self.bound_simulator:
            return f"session: {wire.echo(session)} is not the simulator this generator serves ({self.bound_simulator!r})"
        if not (math.isfinite(request.epoch_s) and request.epoch_s > 0):
            return f"epoch_s: {request.epoch_s!r} must be a positive number of seconds"
        if self._epoch_s is not None and request.epoch_s != self._epoch_s:
            return f"epoch_s: {request.epoch_s!r} differs from the run's {self._epoch_s!r} s (fixed at the first call)"
        t_s = m.from_time(request.epoch_time)
        if not math.isclose(t_s, k * request.epoch_s, rel_tol=1e-9, abs_tol=1e-6):
            return f"epoch_time: {t_s!r} s is not epoch_index {k} x epoch_s {request.epoch_s!r} s"
        last = max(self._released) if self._released else None
        if k in self._released:
            return "" if k == last else f"epoch_index: {k} was released before the last epoch {last}"
        if last is not None and k != last + 1:
            return f"epoch_index: {k} asked, the next epoch is {last + 1}"
        return ""

    def _on_release(self, request: ReleaseDemand.Request, response: ReleaseDemand.Response):
        k = int(request.epoch_index)
        response.session = self.session
        problem = self._check_release(request)
        if problem:
            response.status = ReleaseDemand.Response.STATUS_REFUSED
            response.message = wire.bounded(problem)
            self.get_logger().warning(f"refused a release call: {response.message}")
            return response
        if self.bound_simulator is None:
            self.bound_simulator, self._epoch_s = request.session, float(request.epoch_s)
            self.get_logger().info(f"serving the simulator of session {request.session!r}")
        if k not in self._released:
            t_s = m.from_time(request.epoch_time)
            ids = []
            # every demand instant up to t, in time order (as uam_sim.studies.experiment.run_scenario)
            while self._next_instant * self.interval_s <= t_s + 1e-9:
                i = self._next_instant
                for req in self.source.requests_at(i * self.interval_s, i):
                    op = req.operator_id or self.operator_id  # a demand file may name the operator
                    self._pub.publish(m.request_to_msg(req, operator_id=op))
                    ids.append(wire.scoped_id(op, req.request_id))
                    self.published += 1
                self._next_instant += 1
            self._released[k] = ids
            self._sync_pub.publish(EpochSync(epoch_index=k, epoch_time=request.epoch_time, sender="request_generator",
                                             requests_published=self.published, session=self.session))
        response.request_ids = self._released[k]
        return response

    def _on_sync(self, msg: EpochSync) -> None:
        # only the simulator this generator serves ends its run (a forged announcement does not)
        if msg.sender == "simulator" and msg.finished and self.bound_simulator is not None \
                and msg.session == self.bound_simulator:
            self.finished = True


def main(args=None) -> int:
    return run_node(RequestGeneratorNode, "request_generator", args, events_executor=True)


if __name__ == "__main__":
    sys.exit(main())
