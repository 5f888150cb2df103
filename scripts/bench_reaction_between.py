"""Benchmark: the reaction between epochs (issue 23) through the node graph against the in-process
runner, same scenario. The graph's nodes (solver, planner, request generator, simulator,
conformance monitor; no recorder) run in this process on one multi-threaded executor, as in the
node tests (test/graph_harness.py), in lockstep; the runner is uam_sim.runner.scenario.run_scenario with
the same configuration (request ids scoped as the planner node scopes them, so both draw the same
disturbances). Prints wall and CPU seconds of each, the plan updates at and between epochs, and
whether the two agree (the property test/test_node_reaction_between.py asserts).

    source scripts/env.sh
    python scripts/bench_reaction_between.py --duration 900 --rate 3 --period 10 --speed-error 0.3

``--period 0`` runs the reaction at epochs only (the graph pipelines the next epoch then, and its
planner sees every fleet state: it is not held equal to the runner in that mode).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test")]


def _updates(plans, duration_s):
    from uam_contract import wire
    from uam_planner.nodes import conversions as m
    return sorted((wire.scoped_id(p.operator_id, p.request_id), int(p.version), p.update_kind,
                   m.from_time(p.effective_time)) for p in plans if int(p.version) > 1
                  and m.from_time(p.effective_time) < duration_s)


def run_graph(a):
    import rclpy
    from rclpy.context import Context
    from conftest import _claim_domain_id, spin_until
    from graph_harness import build_graph, run_to_end, shutdown
    domain_id, lock = _claim_domain_id()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    sim = {"speed_error": a.speed_error, "gust_std_mps": a.gust, "disturbance_seed": a.seed,
           "reaction_period_s": a.period}
    t0, c0 = time.perf_counter(), time.process_time()
    executor, nodes, obs = build_graph(ctx, network=a.network, rate=a.rate, seed=a.seed, duration_s=a.duration,
                                       backend=a.backend, simulator_extra=sim, planner_extra={"reaction": True},
                                       conformance=True)
    try:
        run_to_end(executor, nodes, obs, spin_until, timeout_s=3600.0)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        s, p = nodes["simulator"], nodes["planner"]
        out = {"wall_s": wall, "cpu_s": cpu, "updates": _updates(obs.plans, a.duration),
               "reactions_asked": s.reactions_asked, "blocked_wall_s": s.blocked_wall_s,
               "between_graphs_by_service": p.between_graphs_by_service,
               "approved": sum(1 for x in obs.plans if x.outcome == 0 and int(x.version) <= 1)}
    finally:
        shutdown(executor, nodes)
        rclpy.try_shutdown(context=ctx)
        lock.close()
    return out


def run_runner(a):
    from uam_contract import wire
    from uam_planner.network import load_network
    from uam_sim.world.demand import RequestGenerator
    from uam_sim.studies.experiment import make_config, run_scenario

    class Scoped:
        def __init__(self, d):
            self.d = d

        def requests_at(self, t, i):
            return [dataclasses.replace(r, request_id=wire.scoped_id("generator", r.request_id))
                    for r in self.d.requests_at(t, i)]
    dist = {"speed_error": a.speed_error, "gust_std_mps": a.gust}
    cfg = make_config(epoch_s=30.0, time_limit_s=5.0, audit=False, disturbance={k: v for k, v in dist.items() if v},
                      reaction=True, reaction_period_s=a.period)
    net = load_network(a.network)
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_scenario(net, a.backend, a.rate, a.seed, a.duration, cfg,
                       demand=Scoped(RequestGenerator(net.aerodrome_ids, a.rate, cfg.interval_s, cfg.window_s, a.seed)))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ups = sorted((r["request_id"], int(r["version"]), r["kind"], float(r["t_s"])) for r in res.replans
                 if r["t_s"] < a.duration)
    return {"wall_s": wall, "cpu_s": cpu, "updates": ups, "approved": res.summary["approved"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--network", default=str(ROOT / "config" / "networks" / "tiny.yaml"))
    ap.add_argument("--rate", type=float, default=3.0)
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--backend", default="greedy")
    ap.add_argument("--period", type=float, default=10.0, help="reaction_period_s (0: at epochs only)")
    ap.add_argument("--speed-error", type=float, default=0.3)
    ap.add_argument("--gust", type=float, default=0.0)
    a = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    print(f"commit {commit}; load average {' '.join(open('/proc/loadavg').read().split()[:3])}; "
          f"{pathlib.Path(a.network).name}, rate {a.rate:g}, {a.duration:g} s, seed {a.seed}, {a.backend}, "
          f"speed error {a.speed_error:g}, gusts {a.gust:g}, reaction period {a.period:g} s")
    g = run_graph(a)
    r = run_runner(a)
    for name, x in (("node graph", g), ("in process", r)):
        between = sum(1 for u in x["updates"] if u[3] % 30.0 != 0.0)
        print(f"{name:>10}: wall {x['wall_s']:7.2f} s, CPU {x['cpu_s']:7.2f} s, {x['approved']} approved, "
              f"{len(x['updates'])} updates ({between} between epochs)"
              + (f", {x['reactions_asked']} reactions asked, {x['between_graphs_by_service']} of their graphs "
                 f"through uam/solve_mwis, simulator blocked {x['blocked_wall_s']:.2f} s" if "reactions_asked" in x else ""))
    print(f"same updates (ids, versions, kinds, times): {g['updates'] == r['updates']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
