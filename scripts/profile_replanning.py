#!/usr/bin/env python3
"""Issue 22 (fourth stop): the re-plan decision of ``scripts/measure_replanning.py`` in isolation.

    nice -n 5 .venv/bin/python scripts/profile_replanning.py snapshot --seed 1 --out /tmp/rp1.pkl
    nice -n 5 .venv/bin/python scripts/profile_replanning.py run /tmp/rp1.pkl [--profile] [--repeat 3]

``snapshot`` runs the benchmark's scenario (same city, demand, announcement; re-plan policy
``--policy``) and pickles the arguments of the one ``uam_planner.replanning.replan_steps`` call
(the planner's state at the announcement). ``run`` re-runs that decision from the pickle with the
current code (MWIS graphs solved by the benchmark's ``greedy`` backend), prints its wall and CPU
time (``uptime`` beside them), optionally a cProfile (top entries by cumulative and by self
time), and a SHA-256 of the decision: every plan update's request, version, kind, reason,
effective time and new trajectory (times and points, exact bytes), so two code versions can be
compared decision for decision.
"""
from __future__ import annotations

import argparse
import hashlib
import pickle
import sys
import time

import numpy as np


def _feed(h, x) -> None:
    """Exact bytes of a value: dataclasses field by field, arrays by their bytes."""
    import dataclasses
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        h.update(type(x).__name__.encode())
        for f in dataclasses.fields(x):
            h.update(f.name.encode())
            _feed(h, getattr(x, f.name))
    elif hasattr(x, "times_s") and hasattr(x, "points_m"):   # a Trajectory
        h.update(np.ascontiguousarray(x.times_s).tobytes())
        h.update(np.ascontiguousarray(x.points_m).tobytes())
    elif isinstance(x, np.ndarray):
        h.update(np.ascontiguousarray(x).tobytes())
    elif isinstance(x, (list, tuple)):
        h.update(b"[")
        for y in x:
            _feed(h, y)
        h.update(b"]")
    else:
        h.update(repr(x).encode())


def decision_digest(updates) -> str:
    """SHA-256 of the plan updates: every field, the new and previous flights field by field,
    trajectories by their exact bytes."""
    h = hashlib.sha256()
    for u in updates:
        _feed(h, u)
    return h.hexdigest()


def snapshot(args) -> int:
    sys.path.insert(0, "scripts")
    import measure_replanning as mr
    import uam_planner.replanning as rp
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario
    orig = rp.replan_steps
    saved = {}

    def spy(t_eff, epoch_index, active, requests, network, config, cache, cset, select, departures,
            policy="mwis", affected=None, labels=(), held=()):
        if not saved:
            saved.update(t_eff=t_eff, epoch_index=epoch_index, active=list(active), requests=dict(requests),
                         network=network, config=config, cache=cache, cset=cset, policy=policy,
                         affected=affected, labels=list(labels), held=list(held))
            with open(args.out, "wb") as fh:
                pickle.dump(saved, fh, protocol=pickle.HIGHEST_PROTOCOL)
            print(f"saved the re-plan at t = {t_eff} s ({len(active)} active) to {args.out}", flush=True)
        result = yield from orig(t_eff, epoch_index, active, requests, network, config, cache, cset, select,
                                 departures, policy, affected, labels, held)
        print(f"in the run: {len(result[1])} updates, digest {decision_digest(result[1])}, "
              f"decision {1e3 * result[2].decision_time_s:.0f} ms wall {1e3 * result[2].decision_cpu_s:.0f} ms CPU",
              flush=True)
        raise SystemExit(0)  # the rest of the run is not needed
    rp.replan_steps = spy
    spec = {"synthetic": {"n_nodes": 2000, "n_aerodromes": 100, "seed": 0, "levels_m": mr.LEVELS_M,
                          "pads_per_vertiport": 4}}
    cfg = make_config({"network": spec, "duration_s": 2400.0, "audit": True, "time_limit_s": 10.0,
                       "separation_model": "cylinder", "vertical_separation_m": 30.0, "departure_slot_s": 5.0})
    net = load_network_spec(spec)
    ns = argparse.Namespace(announce=1800.0, lead=600.0, window=3600.0, radius=1000.0)
    try:
        run_scenario(net, "greedy", 3000.0 * 30.0 / 3600.0, args.seed, 2400.0, cfg,
                     before_epoch=mr.Announcer(args.policy, ns))
    except SystemExit:
        pass
    return 0


def run(args) -> int:
    import subprocess
    import uam_planner.replanning as rp
    from uam_planner.planning import departure_slots_s, replan_selector
    from uam_sim.runner.scenario import _solver
    from uam_sim.runner.experiment_config import make_config
    with open(args.pickle, "rb") as fh:
        s = pickle.load(fh)
    cfg = s["config"]
    if args.policy:
        s["policy"] = args.policy  # the same planner state: both policies reach it (the epochs are MWIS)
    solve = _solver("greedy", make_config({"time_limit_s": 10.0}), 0) if s["policy"] == "mwis" else None
    select = replan_selector(solve, cfg, s["epoch_index"], s["t_eff"])
    prof = None
    if args.profile:
        import cProfile
        prof = cProfile.Profile()
    walls, cpus, digest = [], [], None
    for _ in range(args.repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        if prof:
            prof.enable()
        _act, updates, rep = rp.replan(s["t_eff"], s["epoch_index"], s["active"], s["requests"], s["network"], cfg,
                                       s["cache"], s["cset"], select, lambda t, r: departure_slots_s(t, r, cfg),
                                       s["policy"], s["affected"], s["labels"], s["held"])
        if prof:
            prof.disable()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
        d = decision_digest(updates)
        assert digest is None or d == digest, "the decision changed between repeats"
        digest = d
    kinds = {}
    for u in updates:
        kinds[u.kind] = kinds.get(u.kind, 0) + 1
    up = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"{args.pickle}: policy {s['policy']}, {len(s['active'])} active, {len(updates)} updates {kinds}; "
          f"{rep.alternatives} alternatives, {rep.vertices} vertices; digest {digest}; "
          f"wall ms {[round(1e3 * w) for w in walls]}, CPU ms {[round(1e3 * c) for c in cpus]}; uptime: {up}")
    if prof:
        import pstats
        st = pstats.Stats(prof)
        st.sort_stats("cumulative").print_stats(args.top)
        st.sort_stats("tottime").print_stats(args.top)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("snapshot")
    a.add_argument("--seed", type=int, default=1)
    a.add_argument("--policy", default="mwis")
    a.add_argument("--out", required=True)
    b = sub.add_parser("run")
    b.add_argument("pickle")
    b.add_argument("--profile", action="store_true")
    b.add_argument("--repeat", type=int, default=1)
    b.add_argument("--top", type=int, default=30)
    b.add_argument("--policy", default=None, help="re-plan policy (default: the snapshot's)")
    args = ap.parse_args(argv)
    return snapshot(args) if args.cmd == "snapshot" else run(args)


if __name__ == "__main__":
    sys.exit(main())
