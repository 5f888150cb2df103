#!/usr/bin/env python3
"""Issue 22's benchmark: a restriction appears over the busiest area of the synthetic city.

    nice -n 5 .venv/bin/python scripts/measure_replanning.py --seeds 3

Through the in-process runner ``uam_sim.runner.scenario.run_scenario`` (the planner library, no ROS):
``generate_network(--nodes, --vertiports, seed 0, levels 60/90/120/150 m, 4 pads)``, the
expanded airspace (cylinder H 100 m / V 30 m, ``--slot-s`` departure slots), ``--per-hour``
requests per hour from the seeded ``RequestGenerator``, epochs of 30 s, MWIS backend ``--method``.
At the first epoch at or after ``--announce`` s a ``before_epoch`` hook announces a circle of
radius ``--radius`` m, every altitude, in force from announce + ``--lead`` s for ``--window`` s,
centred on the corridor node with the most airborne aircraft within ``--radius`` of it at that
instant (the busiest area; a function of the planner's state, so the same in every arm of a
seed). It is applied in that epoch (``Planner.update_constraint``), so every affected flight is
decided within it. Each seed runs twice from the same demand, re-plan policy ``mwis`` and
``firstfit`` (the epochs themselves are MWIS in both, so both reach the announcement with the
same flights). Per run: intents (accepted or airborne) at the announcement, affected flights by
class and what happened to them, the re-plan decision wall time, the audit of what flew (every
version from the instant it took effect, in the run's separation model: losses) and the
constraint incursions (``uam_sim.audit.flown_audit.incursions``, through the runner). Then MWIS against first-fit
per seed (``uam_sim.reports.stats.paired``: mean difference and 95 % t interval over seeds): flights
still reaching their destination, flights saved (not cancelled, not a contingency), mean added
delay of those reaching their destination. Wall times depend on the machine's load (printed
with ``uptime``); the decisions do not.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

import numpy as np

from uam_planner.constraints import Constraint
from uam_sim.runner.experiment_config import make_config
from uam_sim.runner.network_spec import load_network_spec
from uam_sim.runner.scenario import run_scenario
from uam_sim.reports.stats import mean_interval, paired

LEVELS_M = [60.0, 90.0, 120.0, 150.0]
REACH = ("kept", "rerouted", "retimed")
SAVED = REACH + ("diverted",)


class Announcer:
    """before_epoch hook: sets the re-plan policy and announces the restriction once."""

    def __init__(self, policy: str, args):
        self.policy, self.args = policy, args
        self.done = False
        self.info: dict = {}

    def __call__(self, planner, t_s, epoch_index):
        from dataclasses import replace
        from scipy.spatial import cKDTree
        if planner.config.replan_policy != self.policy:
            planner.config = replace(planner.config, replan_policy=self.policy)
        if self.done or t_s < self.args.announce - 1e-9:
            return
        self.done = True
        net = planner.network
        active = [f for f in planner.active if f.arrival_s >= t_s]
        airborne = [f for f in active if f.departure_s < t_s]
        pos = np.array([f.trajectory.position_at(t_s)[:2] for f in airborne]).reshape(-1, 2)
        corridor = np.flatnonzero(~np.asarray(net.is_aerodrome))
        xy = net.enu_m[corridor, :2]
        counts = np.array([len(x) for x in cKDTree(pos).query_ball_point(xy, self.args.radius)]) \
            if len(pos) else np.zeros(len(xy), int)
        best = int(np.argmax(counts))  # ties: the lowest node index
        centre = (float(xy[best, 0]), float(xy[best, 1]))
        start = t_s + self.args.lead
        c = Constraint("tfr-busiest", 1, "restriction over the busiest area", start,
                       start + self.args.window, center_m=centre, radius_m=self.args.radius,
                       announce_s=t_s)
        reason = planner.update_constraint("add", c, t_s)
        assert reason is None, reason
        self.info = {"t_s": float(t_s), "intents": len(active), "airborne": len(airborne),
                     "accepted": len(active) - len(airborne), "centre": centre,
                     "node": net.node_ids[int(corridor[best])], "airborne_inside": int(counts[best])}


class ReplanClock:
    """observer: keeps the epoch's ReplanReport."""

    def __init__(self):
        self.reports = []
        self.updates = []

    def __call__(self, t_s, epoch_index, submitted, refused, result):
        if result.report.replan is not None:
            self.reports.append(result.report.replan)
        self.updates.extend(result.plan_updates)


class DecisionWaits:
    """Where a decision's wall time goes when it is not this process's CPU (issue 22, third
    stop): around each ``uam_planner.replanning.replan_steps`` (the batch re-plan), the
    process's voluntary context switches (it waited: I/O, a pipe to a solver worker, a lock),
    involuntary ones (it was runnable but another process had the core: the machine's load),
    major page faults (files read from disk) and the modules first imported in it."""

    def __init__(self):
        import uam_planner.replanning as replanning
        self.rows, self._mod, self._orig = [], replanning, replanning.replan_steps
        replanning.replan_steps = self._steps

    def _steps(self, *a, **k):
        import gc
        import resource
        gcs = {"s": 0.0, "n": [0, 0, 0], "t0": 0.0}

        def on_gc(phase, info):  # the cyclic garbage collector's CPU time inside the decision
            if phase == "start":
                gcs["t0"] = time.process_time()
            else:
                gcs["s"] += time.process_time() - gcs["t0"]
                gcs["n"][info["generation"]] += 1
        gc.callbacks.append(on_gc)
        r0, mods = resource.getrusage(resource.RUSAGE_SELF), set(sys.modules)
        try:
            result = yield from self._orig(*a, **k)
        finally:
            gc.callbacks.remove(on_gc)
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        self.rows.append({"waits": r1.ru_nvcsw - r0.ru_nvcsw, "preempted": r1.ru_nivcsw - r0.ru_nivcsw,
                          "major_faults": r1.ru_majflt - r0.ru_majflt,
                          "imported": sorted(m for m in set(sys.modules) - mods if "." not in m),
                          "gc_cpu_ms": round(1e3 * gcs["s"]), "gc_collections": gcs["n"],
                          "gc_tracked_objects": len(gc.get_objects())})
        return result

    def close(self):
        self._mod.replan_steps = self._orig


def one_run(net, cfg, seed: int, policy: str, args) -> dict:
    ann, clock = Announcer(policy, args), ReplanClock()
    rate = args.per_hour * 30.0 / 3600.0
    waits = DecisionWaits()
    t0 = time.perf_counter()
    try:
        res = run_scenario(net, args.method, rate, seed, args.duration, cfg, observer=clock, before_epoch=ann)
    finally:
        waits.close()
    wall = time.perf_counter() - t0
    rows = res.replans
    for r in clock.updates:
        if r.kind == "contingency":
            print(f"  contingency {r.request_id}: {r.reason}", flush=True)
    rep = clock.reports[0] if clock.reports else None
    kinds = {k: sum(r["kind"] == k for r in rows) for k in
             ("kept", "rerouted", "retimed", "diverted", "cancelled", "contingency")}
    by_class = {}
    for cls, flag in (("airborne", True), ("not departed", False)):
        sub = [r for r in rows if r["airborne"] == flag]
        by_class[cls] = {k: sum(r["kind"] == k for r in sub) for k in kinds if any(r["kind"] == k for r in sub)}
    reach = [r for r in rows if r["kind"] in REACH]
    out = {"seed": seed, "policy": policy, **ann.info, "affected": len(rows), "kinds": kinds,
           "by_class": by_class, "reach": len(reach), "saved": sum(r["kind"] in SAVED for r in rows),
           "reach_delay_mean_s": float(np.mean([r["added_delay_s"] for r in reach])) if reach else float("nan"),
           "decision_s": rep.decision_time_s if rep else float("nan"),
           "decision_cpu_s": rep.decision_cpu_s if rep else float("nan"),
           "stage2": rep.stage2 if rep else 0, "graphs_solved": rep.graphs_solved if rep else 0,
           "decision_waits": waits.rows[0] if waits.rows else {},
           "solve_s": rep.solve_time_s if rep else float("nan"),
           "vertices": rep.vertices if rep else 0, "edges": rep.edges if rep else 0,
           "alternatives": rep.alternatives if rep else 0, "fallback": rep.fallback if rep else False,
           "losses": res.audit.get("losses"), "min_sep": res.audit.get("min_separation_m"),
           "pairs": res.audit.get("pairs_checked"), "incursions": res.summary.get("incursions"),
           "loss_pairs": res.audit.get("loss_pairs", [])[:3], "approved": res.summary["approved"],
           "requests": res.summary["requests"], "wall_s": wall,
           # the decision itself, exactly (every plan update's fields and trajectories' bytes):
           # code changes for speed must leave it unchanged (issue 22, fourth stop)
           "updates_sha256": decision_digest(clock.updates)}
    handled = out["affected"] == (rep.affected + rep.pulled_in if rep else 0)
    contingent = {r["request_id"] for r in rows if r["kind"] == "contingency"}
    # issue 22: contingencies are deconflicted as fixed flights; what is left is counted apart:
    # flown not deconflicted (the cascade's bound), and flights with no way out (already inside)
    unresolved = {u.request_id for u in clock.updates if u.kind == "contingency" and "not deconflicted" in u.reason}
    unavoidable = {u.request_id for u in clock.updates if u.kind == "contingency" and "cannot be avoided" in u.reason}
    out.update({"cascade_rounds": rep.cascade_rounds if rep else 0, "pulled_in": rep.pulled_in if rep else 0,
                "contingencies_fixed": rep.contingencies_fixed if rep else 0,
                "unresolved": len(unresolved), "unavoidable": len(unavoidable)})
    pairs = res.audit.get("loss_pairs", [])
    out["losses_with_unresolved"] = sum(1 for a, b, *_ in pairs if a in unresolved or b in unresolved) \
        if (res.audit.get("losses") or 0) <= 20 else None
    incs = res.audit.get("incursions") or []
    out["incursions_unavoidable"] = sum(1 for x in incs if x[0] in unavoidable)
    out["incursions_list"] = incs[:5]
    out["losses_without_contingency"] = sum(1 for a, b, *_ in res.audit.get("loss_pairs", [])
                                            if a not in contingent and b not in contingent) \
        if (res.audit.get("losses") or 0) <= 20 else None
    if args.graph_inputs and "centre" in ann.info:
        write_graph_inputs(net, seed, ann.info, args)
    if args.out:
        import json
        with open(args.out, "a") as fh:
            fh.write(json.dumps(out, default=str) + "\n")
    print(f"seed {seed} {policy}: t = {out.get('t_s')} s, {out.get('intents')} intents "
          f"({out.get('airborne')} airborne, {out.get('accepted')} accepted), centre {out.get('node')} "
          f"{out.get('centre')} with {out.get('airborne_inside')} airborne within {args.radius:g} m; "
          f"affected {out['affected']} {out['by_class']} (all decided in the epoch: {handled}); "
          f"graph {out['alternatives']} alternatives, {out['vertices']} vertices, {out['edges']} edges; "
          f"decision {1e3 * out['decision_s']:.0f} ms wall, {1e3 * out['decision_cpu_s']:.0f} ms CPU "
          f"(off CPU: {out['decision_waits']}) "
          f"(solve {1e3 * out['solve_s']:.0f} ms, {out['stage2']} flights with stage-2 alternatives, "
          f"fallback {out['fallback']}); reach destination {out['reach']}, saved {out['saved']}, "
          f"mean added delay {out['reach_delay_mean_s']:.1f} s; audit of what flew: {out['losses']} "
          f"losses in {out['pairs']} pairs (min {out['min_sep']}; without a contingency flight: "
          f"{out['losses_without_contingency']}), {out['incursions']} incursions "
          f"{out['loss_pairs']}; contingencies: {out['contingencies_fixed']} fixed, {out['unresolved']} "
          f"flown not deconflicted, {out['unavoidable']} with no way out; {out['pulled_in']} flights pulled in, "
          f"{out['cascade_rounds']} rounds; losses with an unresolved contingency {out['losses_with_unresolved']}, "
          f"incursions by flights with no way out {out['incursions_unavoidable']}; {out['approved']}/{out['requests']} approved; wall {wall:.0f} s; "
          f"updates sha256 {out['updates_sha256'][:16]}; uptime: {uptime()}", flush=True)
    return out


def decision_digest(updates) -> str:
    """SHA-256 of plan updates (``scripts/profile_replanning.decision_digest``)."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from profile_replanning import decision_digest as digest
    return digest(updates)


def write_graph_inputs(net, seed: int, info: dict, args) -> None:
    """The same scenario for the node graph (issue 22, "the same scenario through the node
    graph"): the city as a network file and this seed's restriction as an announced GeoJSON
    circle (ENU frame), for ``scripts/run_fleet.sh --network DIR/city.yaml --constraints
    DIR/tfr-seed<N>.geojson --seed N --rate <per-hour / 120> --backend <method> --slot-s ...``."""
    import json
    from pathlib import Path
    from uam_planner.network import save_network_yaml
    d = Path(args.graph_inputs)
    d.mkdir(parents=True, exist_ok=True)
    if not (d / "city.yaml").exists():
        save_network_yaml(net, d / "city.yaml", header=f"scripts/measure_replanning.py: generate_network("
                          f"{args.nodes}, {args.vertiports}, seed 0, levels 60/90/120/150 m, 4 pads)")
    start = info["t_s"] + args.lead
    doc = {"type": "FeatureCollection", "frame": "enu", "features": [{
        "type": "Feature", "geometry": {"type": "Point", "coordinates": list(info["centre"])},
        "properties": {"id": "tfr-busiest", "version": 1, "reason": "restriction over the busiest area",
                       "radius_m": args.radius, "lower_m": -1000.0, "upper_m": 100000.0,
                       "start_s": start, "end_s": start + args.window, "announce_s": info["t_s"]}}]}
    (d / f"tfr-seed{seed}.geojson").write_text(json.dumps(doc, indent=1) + "\n")


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "load " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def summarize(runs: dict) -> None:
    """Per policy: decision times, affected, losses, incursions; then MWIS - first-fit paired
    over the seeds both have."""
    for p in runs:
        if not runs[p]:
            continue
        d = [r["decision_s"] for r in runs[p].values()]
        dc = [r["decision_cpu_s"] for r in runs[p].values()]
        m, lo, hi = mean_interval([r["affected"] for r in runs[p].values()])
        kinds = {k: sum(r["kinds"][k] for r in runs[p].values()) for k in next(iter(runs[p].values()))["kinds"]}
        print(f"{p} ({len(d)} seeds): decision wall median {1e3 * statistics.median(d):.0f} ms (max {1e3 * max(d):.0f}), "
              f"CPU median {1e3 * statistics.median(dc):.0f} ms (max {1e3 * max(dc):.0f}); "
              f"affected mean {m:.1f} [{lo:.1f}, {hi:.1f}], in all {kinds}; intents "
              f"{[r['intents'] for r in runs[p].values()]}; losses {[r['losses'] for r in runs[p].values()]} "
              f"(without a contingency flight {[r['losses_without_contingency'] for r in runs[p].values()]}), "
              f"incursions {[r['incursions'] for r in runs[p].values()]} (by flights with no way out "
              f"{[r.get('incursions_unavoidable') for r in runs[p].values()]}); contingencies fixed "
              f"{[r.get('contingencies_fixed') for r in runs[p].values()]}, unresolved "
              f"{[r.get('unresolved') for r in runs[p].values()]}, no way out "
              f"{[r.get('unavoidable') for r in runs[p].values()]}; pulled in "
              f"{[r.get('pulled_in') for r in runs[p].values()]}")
    if runs.get("mwis") and runs.get("firstfit"):
        a, b = runs["mwis"], runs["firstfit"]
        for metric in ("reach", "saved", "reach_delay_mean_s"):
            pr = paired({s: a[s][metric] for s in a}, {s: b[s][metric] for s in b})
            print(f"mwis - firstfit {metric}: {pr.text(1)} over {pr.n} seeds (t, 95 %) "
                  f"(mwis {[round(a[s][metric], 1) for s in sorted(a)]}, "
                  f"firstfit {[round(b[s][metric], 1) for s in sorted(b)]})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=2400.0, help="simulated seconds of demand")
    ap.add_argument("--announce", type=float, default=1800.0, help="announcement time [s]")
    ap.add_argument("--lead", type=float, default=600.0, help="in force this long after the announcement [s]")
    ap.add_argument("--window", type=float, default=3600.0, help="how long it stays in force [s]")
    ap.add_argument("--radius", type=float, default=1000.0, help="circle radius [m] (1000: a 2 km zone)")
    ap.add_argument("--per-hour", type=float, default=3000.0)
    ap.add_argument("--method", default="greedy", help="MWIS backend of the epochs and of the re-plan")
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--nodes", type=int, default=2000)
    ap.add_argument("--vertiports", type=int, default=100)
    ap.add_argument("--slot-s", type=float, default=5.0)
    ap.add_argument("--policies", nargs="+", default=["mwis", "firstfit"])
    ap.add_argument("--out", default=None, help="append one JSON line per run to this file")
    ap.add_argument("--graph-inputs", default=None,
                    help="write the city network and each seed's restriction (GeoJSON) here, for run_fleet.sh")
    ap.add_argument("--summarize", default=None, help="only summarise the JSON lines of this file")
    args = ap.parse_args(argv)
    if args.summarize:
        import json
        runs: dict = {}
        for line in open(args.summarize):
            r = json.loads(line)
            runs.setdefault(r["policy"], {})[r["seed"]] = r
        summarize(runs)
        return 0
    spec = {"synthetic": {"n_nodes": args.nodes, "n_aerodromes": args.vertiports, "seed": 0,
                          "levels_m": LEVELS_M, "pads_per_vertiport": 4}}
    cfg = make_config({"network": spec, "duration_s": args.duration, "audit": True,
                       "time_limit_s": args.time_limit, "separation_model": "cylinder",
                       "vertical_separation_m": 30.0, "departure_slot_s": args.slot_s})
    net = load_network_spec(spec)
    print(f"city {args.nodes} nodes / {args.vertiports} vertiports, {args.per_hour:g} requests/h, "
          f"{args.duration:g} s, circle r = {args.radius:g} m announced at {args.announce:g} s, in force "
          f"from +{args.lead:g} s for {args.window:g} s; method {args.method}; uptime: {uptime()}", flush=True)
    runs = {p: {} for p in args.policies}
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for p in args.policies:
            runs[p][seed] = one_run(net, cfg, seed, p, args)
    summarize(runs)
    print(f"uptime: {uptime()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
