"""Planning-cycle time with a rolling horizon (issue 21): layered Singapore ("both": pads, 4
levels, cylinder, 5 s slots), 20 requests per 30 s, objective count, seed 0, over the in-process
runner. Prints one row per (window / lead, H): cycle (prepare + solve + commit) median, p95 and
max over the epochs, graph sizes, approvals, mean delay, and a hash of the decisions (request ->
epoch, candidate) so that two versions of the planner can be compared on the same plans.

    python scripts/bench_horizon.py [--backend exact] [--duration 600] [--horizons 1,5,10]
        [--settings 60:0,120:120] [--in-process [--cpu]]

``--in-process``: the planner alone with the greedy MWIS in this process (no solver workers, no
time limit: deterministic, so two versions give the same decisions hash), printing the prepare's
median and max and its phases summed over the run. ``--cpu`` (with ``--in-process``): every
time the planner reports is CPU time of this process (``time.perf_counter`` is replaced by
``time.process_time`` here before the planner is imported), the measure to compare on a shared
machine; the prepare's median is then its CPU median.

Wall time is measured here only (and printed with the load average); nothing decides on it.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics


def run(h: int, window_s: float, lead_s: float, backend: str, duration_s: float) -> dict:
    from uam_planner.network import load_network
    from uam_sim.runner.experiment_config import make_config, resolve_path
    from uam_sim.runner.scenario import run_scenario
    cfg = make_config(airspace_mode="both", objective="count", horizon_epochs=h,
                      window_s=window_s, lead_time_s=lead_s, time_limit_s=5.0, workers=1)
    res = run_scenario(load_network(resolve_path(cfg.network)), backend, 20, 0, duration_s, cfg)
    cyc = sorted(e["planning_time_s"] + e["solve_time_s"] for e in res.epochs)
    s = res.summary
    return {"window": window_s, "lead": lead_s, "H": h, "median_s": statistics.median(cyc),
            "p95_s": cyc[int(round(0.95 * (len(cyc) - 1)))], "max_s": cyc[-1],
            "prepare_median_s": statistics.median(e["planning_time_s"] for e in res.epochs),
            "mean_vertices": s["mean_vertices"], "max_vertices": s["max_vertices"],
            "approved": s["approved"], "requests": s["requests"], "pending_end": s["pending_end"],
            "delay_mean_s": s["delay_mean_s"], "fallbacks": s["fallbacks"],
            "decisions": hashlib.sha256(json.dumps(sorted(res.decisions().items())).encode())
            .hexdigest()[:12]}


def run_in_process(h: int, window_s: float, lead_s: float, duration_s: float) -> dict:
    """The runner's loop (generator, Planner) with greedy solved in process: prepare times and
    phases, and the decisions hash."""
    from uam_planner.network import load_network
    from uam_planner.planning import Planner
    from uam_sim.world.demand import RequestGenerator
    from uam_sim.runner.experiment_config import make_config, resolve_path
    from uam_solvers.greedy import greedy_mwis

    class Answer:
        def __init__(self, selected):
            self.selected, self.backend = selected, "greedy"

    cfg = make_config(airspace_mode="both", objective="count", horizon_epochs=h, window_s=window_s,
                      lead_time_s=lead_s, workers=1)
    net = load_network(resolve_path(cfg.network))
    planner = Planner(net, cfg.planning_config("greedy", 0),
                      solve_mwis=lambda w, e, g: Answer(greedy_mwis(w, e)))
    gen = RequestGenerator(net.aerodrome_ids, 20, cfg.interval_s, cfg.window_s, 0, lead_time_s=lead_s)
    prep, phases, decisions = [], {}, []
    for e in range(int(duration_s // cfg.epoch_s)):
        t = e * cfg.epoch_s
        for r in gen.requests_at(t, e):
            planner.submit(r)
        res = planner.plan(t, e)
        prep.append(res.report.planning_time_s)
        for k, v in res.report.phase_times_s.items():
            phases[k] = phases.get(k, 0.0) + v
        decisions += [(f.request_id, e, f.candidate_index) for f in res.approved]
    return {"prepare_median_s": statistics.median(prep), "prepare_max_s": max(prep),
            "phases": phases, "approved": len(decisions),
            "decisions": hashlib.sha256(json.dumps(decisions).encode()).hexdigest()[:12]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="exact")
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--horizons", default="1,5,10")
    ap.add_argument("--settings", default="60:0,120:120", help="window_s:lead_s,...")
    ap.add_argument("--in-process", action="store_true",
                    help="the planner with greedy in process: prepare times, phases, decisions")
    ap.add_argument("--cpu", action="store_true",
                    help="with --in-process: the planner's times are CPU times of this process")
    a = ap.parse_args(argv)
    if a.in_process:
        if a.cpu:  # a benchmark's clock only: the planner decides nothing on time
            import time
            time.perf_counter = time.process_time
        print(f"load average {os.getloadavg()[0]:.2f}, in-process greedy"
              + (", times are CPU seconds" if a.cpu else ", times are wall seconds"))
        for setting in a.settings.split(","):
            w, lead = (float(x) for x in setting.split(":"))
            for h in (int(x) for x in a.horizons.split(",")):
                r = run_in_process(h, w, lead, a.duration)
                ph = ", ".join(f"{k[:-2]} {v:.2f}" for k, v in r["phases"].items())
                print(f"{w:g} s / {lead:g} s, H = {h}: prepare median {r['prepare_median_s']:.3f} s, "
                      f"max {r['prepare_max_s']:.3f} s; approved {r['approved']}; decisions "
                      f"{r['decisions']}; phases over the run [s]: {ph}", flush=True)
        print(f"load average {os.getloadavg()[0]:.2f}")
        return 0
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}, backend {a.backend}")
    print("| window / lead | H | cycle median [s] | p95 [s] | max [s] | prepare median [s] | "
          "mean / max vertices | approved (of requests) | delay mean [s] | decisions |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for setting in a.settings.split(","):
        w, lead = (float(x) for x in setting.split(":"))
        for h in (int(x) for x in a.horizons.split(",")):
            r = run(h, w, lead, a.backend, a.duration)
            print(f"| {w:g} s / {lead:g} s | {h} | {r['median_s']:.3f} | {r['p95_s']:.3f} | "
                  f"{r['max_s']:.3f} | {r['prepare_median_s']:.3f} | {r['mean_vertices']:,.0f} / "
                  f"{r['max_vertices']:,} | {r['approved']} of {r['requests']} "
                  f"({r['pending_end']} pending) | {r['delay_mean_s']:.1f} | {r['decisions']} |",
                  flush=True)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
