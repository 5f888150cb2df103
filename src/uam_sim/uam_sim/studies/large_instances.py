"""Where optimisation pays on large instances: matched shadow solves of the large city's epochs,
and MWIS against first-fit re-planning after a restriction over a busy area.

    nice -n 10 python -m uam_sim.large_instances --config config/large-instances.yaml
    nice -n 10 python -m uam_sim.large_instances --config config/large-instances.yaml --stage replanning
    python -m uam_sim.large_instances_report docs/large-instances    # the report from the tables

Two stages, each writing committed tables to the config's ``out`` (docs/large-instances):

- ``solves``: for each rate of ``record.rates_per_hour``, the city ``record.city``
  (:data:`uam_planner.synthetic.CITIES`) is planned in process for the rate's duration, as
  ``scripts/bench_epoch_cpu.py --lazy-routes`` plans it (cylinder H 100 m / V 30 m, 5 s departure
  slots, the paper's demand generator, window 60 s, routes searched when a pair is first
  requested), under the policy ``record.method`` (first-fit, the decision study's E0 reference
  policy: it builds the MWIS policy's instance and decides fast). Every epoch is planned, but
  only those at ``t >= record.record_from_s`` (per rate: the steady-state window; earlier
  epochs are the warm-up that fills the sky) keep their instance; of those, a seeded sample per
  size bin (:func:`uam_sim.studies.decision_study.e0_sample`) is solved
  by every solver of ``solve.backends`` at ``solve.time_limit_s`` and by the reference
  (``solve.reference``), each through :func:`uam_sim.studies.decision_study.e0_solve_rows`
  (E0's solve, so the rows mean what E0's mean). ``instances.csv``: every recorded epoch (size,
  requests, airborne, whether sampled); ``solves.csv.gz``: one row per (instance, solver).
- ``replanning``: ``scripts/measure_replanning.py`` with ``replanning.args`` (each seed runs
  with re-plan policy ``mwis`` and ``firstfit``); ``replanning.csv``: its per-seed rows.

Each rate's rows and the re-planning runs are kept as cells in ``cells`` (not committed), keyed
by their parameters and the run code's version (:func:`uam_sim.runner.sweep.code_version`), so a
stage that stopped resumes. No wall clock enters a decision: wall times are measured, not used.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import yaml

from ..runner.files import write_csv, write_json_atomic

STAGES = ("solves", "replanning")
ROOT = Path(__file__).resolve().parents[4]


def load_config(path) -> dict:
    """config/large-instances.yaml as a dict; a missing section or key is named."""
    cfg = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    for section, keys in (("record", ("city", "city_seed", "method", "rates_per_hour",
                                      "duration_s", "record_from_s", "seed", "slot_s",
                                      "vertical_separation_m")),
                          ("solve", ("backends", "time_limit_s", "reference", "bins", "per_bin",
                                     "seed")),
                          ("replanning", ("args",))):
        if not isinstance(cfg.get(section), dict):
            raise ValueError(f"{path}: section {section!r} is missing")
        for k in keys:
            if k not in cfg[section]:
                raise ValueError(f"{path}: {section}.{k} is missing")
    rates, durs = cfg["record"]["rates_per_hour"], cfg["record"]["duration_s"]
    if not isinstance(durs, list) or len(durs) != len(rates):
        raise ValueError(f"{path}: record.duration_s must list one duration per rate "
                         f"({len(rates)}), got {durs!r}")
    _check_record_from(path, cfg["record"].get("record_from_s"), rates, durs)
    spb = cfg["solve"].setdefault("steady_per_bin", cfg["solve"]["per_bin"])
    if spb is not None and (isinstance(spb, bool) or not isinstance(spb, int) or spb < 1):
        raise ValueError(f"{path}: solve.steady_per_bin = {spb!r}: must be an integer >= 1 or "
                         f"null (every instance kept at steady state)")
    if "firstfit" not in cfg["solve"]["backends"]:
        raise ValueError(f"{path}: solve.backends must include 'firstfit' (the baseline every "
                         f"gain is read against), got {cfg['solve']['backends']!r}")
    cfg.setdefault("out", "docs/large-instances")
    cfg.setdefault("cells", "results/large-instances")
    return cfg


def _check_record_from(path, froms, rates, durs) -> None:
    """record.record_from_s: one start of the recorded window [s] per rate, a number >= 0 and
    below the rate's duration (at least one epoch is recorded); ValueError naming the value."""
    if not isinstance(froms, list) or len(froms) != len(rates):
        raise ValueError(f"{path}: record.record_from_s must list one start [s] per rate "
                         f"({len(rates)}), got {froms!r}")
    for rate, start, dur in zip(rates, froms, durs):
        ok = isinstance(start, (int, float)) and not isinstance(start, bool)
        if not ok or not (0.0 <= float(start) < float(dur)):
            raise ValueError(f"{path}: record.record_from_s = {start!r} for {rate} requests/h: "
                             f"must be a number >= 0 and below its duration_s ({dur})")


def run_name(cfg: dict, per_hour) -> str:
    return f"{cfg['record']['city']}-r{int(per_hour)}"


def record_city(city: str, city_seed: int, per_hour: float, duration_s: float, seed: int,
                method: str = "firstfit", slot_s: float = 5.0,
                vertical_separation_m: float = 30.0, record_from_s: float = 0.0) -> tuple[list, list]:
    """Plan ``duration_s`` [s] of the named city at ``per_hour`` requests per hour in process
    under ``method`` (``firstfit`` or ``fifo``; the planner's own baselines, no solver), as
    ``scripts/bench_epoch_cpu.py --lazy-routes`` builds the run. Every epoch is planned (the
    warm-up fills the sky), but only those at ``t >= record_from_s`` keep their instance: an
    early epoch of a busy city holds ~27 M edges, so keeping every epoch's would not fit in
    memory. Returns ([(epoch, t_s, kept instance)] of every recorded epoch with a conflict graph
    (:func:`kept_problem` builds its MwisProblem; ``.n`` is its vertex count), [one dict per
    epoch: its counts, CPU seconds and ``warmup`` (t < record_from_s)])."""
    from uam_planner.planning import AirspaceConfig, Planner, PlanningConfig
    from uam_planner.synthetic import generate_city

    from ..world.demand import RequestGenerator
    net = generate_city(city, city_seed)
    cfg = PlanningConfig(airspace=AirspaceConfig("cylinder", float(vertical_separation_m),
                                                 float(slot_s)),
                         backend="greedy", seed=seed, precompute_routes=False)
    planner = Planner(net, cfg, method)
    demand = RequestGenerator(net.aerodrome_ids, per_hour * cfg.epoch_s / 3600.0, cfg.epoch_s,
                              60.0, seed)
    found, epochs = [], []
    for e in range(int(np.ceil(duration_s / cfg.epoch_s - 1e-9))):
        t = e * cfg.epoch_s
        c = time.process_time()
        for r in demand.requests_at(t, e):
            reason = planner.submit(r)
            if reason is not None:
                raise ValueError(f"request {r.request_id} refused: {reason}")
        rep = planner.plan(t, e).report
        warmup = t < float(record_from_s)
        epochs.append({"epoch": e, "t_s": t, "eligible": rep.eligible, "vertices": rep.vertices,
                       "edges": rep.edges, "approved": rep.approved,
                       "airborne": rep.active_flights - rep.approved,
                       "cpu_s": time.process_time() - c, "warmup": warmup})
        if not warmup and rep.vertices > 0:
            found.append((e, t, _kept(rep)))
    return found, epochs


def _kept(report) -> SimpleNamespace:
    """An epoch's instance as its report holds it (int32 edges, copied: a few bytes per edge);
    the MwisProblem, ~3x that, is built only for the sampled ones (:func:`kept_problem`)."""
    return SimpleNamespace(n=int(report.vertices), vertices=int(report.vertices),
                           weights=np.array(report.weights, dtype=np.float64),
                           edges_array=np.array(report.edges_array, dtype=np.int32),
                           vertex_request_ids=list(report.vertex_request_ids))


def kept_problem(kept: SimpleNamespace):
    """The MwisProblem of a kept instance (weights, edges, one group per request)."""
    from ..runner.scenario import problem_from_report
    return problem_from_report(kept)


def _key(cfg: dict, per_hour, duration_s, record_from_s) -> str:
    from ..runner.sweep import code_version
    params = {"record": {**cfg["record"], "rates_per_hour": per_hour, "duration_s": duration_s,
                         "record_from_s": record_from_s},
              "solve": cfg["solve"]}
    digest = hashlib.sha256(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:16]
    return f"solves_{run_name(cfg, per_hour)}_{digest}_c{code_version()}"


def solve_rate(cfg: dict, per_hour, duration_s, cells: Path, progress: bool = True,
               record_from_s: float = 0.0) -> dict:
    """One rate's cell: record (instances kept from ``record_from_s`` on), sample the kept ones,
    solve by every solver and the reference; cached."""
    from ..runner.sweep import _commit, code_version
    from .decision_study import REFERENCE, e0_sample, e0_solve_rows
    key = _key(cfg, per_hour, duration_s, record_from_s)
    path = cells / f"{key}.json"
    if path.exists():
        return json.loads(path.read_text())
    rec, sol = cfg["record"], cfg["solve"]
    load0 = os.getloadavg()[0]
    found, epochs = record_city(rec["city"], int(rec["city_seed"]), float(per_hour),
                                float(duration_s), int(rec["seed"]), rec["method"],
                                float(rec["slot_s"]), float(rec["vertical_separation_m"]),
                                float(record_from_s))
    per_bin = sol["per_bin"] if float(record_from_s) == 0 else sol["steady_per_bin"]
    picked_kept = e0_sample(found, list(sol["bins"]), per_bin, int(sol["seed"]))
    picked = {int(ep) for ep, _t, _p in picked_kept}
    if progress:
        print(f"{run_name(cfg, per_hour)}: {len(epochs) - len(found)} warm-up or empty epochs, "
              f"{len(found)} instances kept ({', '.join(str(p.n) for _e, _t, p in found)} "
              f"vertices); sampled epochs {sorted(picked)}", flush=True)
    del found  # only the sample's instances are built and solved
    sample = [(e, t, kept_problem(k)) for e, t, k in picked_kept]
    del picked_kept
    rows = []
    for solver in list(sol["backends"]) + [REFERENCE]:
        ref = solver == REFERENCE
        backend = sol["reference"]["backend"] if ref else solver
        limit = float(sol["reference"]["time_limit_s"] if ref else sol["time_limit_s"])
        for r in e0_solve_rows(sample, solver, backend, limit, int(rec["seed"])):
            rows.append({**r, "load": round(os.getloadavg()[0], 2)})
        if progress:
            done = [r for r in rows if r["solver"] == solver]
            print(f"  {solver}: " + ", ".join(f"{r['objective']:.3f} in {r['wall_s']:.2f} s"
                                             + (" (fallback)" if r["fallback"] else "")
                                             for r in done), flush=True)
    name = run_name(cfg, per_hour)
    for r in rows:
        r.update({"run": name, "rate_per_hour": per_hour})
    for ep in epochs:
        ep.update({"run": name, "rate_per_hour": per_hour, "record_from_s": record_from_s,
                   "sampled": ep["epoch"] in picked, "load": round(load0, 2)})
    cell = {"key": key, "run": name, "rows": rows, "epochs": epochs, "ran_at": _commit(),
            "code_version": code_version()}
    cells.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, cell)
    return cell


SOLVE_COLUMNS = ["run", "rate_per_hour", "epoch", "t_s", "vertices", "edges", "solver", "backend",
                 "time_limit_s", "objective", "count", "proven_optimal", "fallback", "wall_s",
                 "load", "commit", "code_version"]
EPOCH_COLUMNS = ["run", "rate_per_hour", "record_from_s", "epoch", "t_s", "warmup", "eligible",
                 "vertices", "edges", "approved", "airborne", "sampled", "cpu_s", "load"]


def run_solves(cfg: dict, out: Path, progress: bool = True) -> dict:
    cells = Path(cfg["cells"])
    rows, epochs = [], []
    rec = cfg["record"]
    for per_hour, dur, start in zip(rec["rates_per_hour"], rec["duration_s"], rec["record_from_s"]):
        cell = solve_rate(cfg, per_hour, dur, cells, progress, start)
        ran = {"commit": cell["ran_at"], "code_version": cell["code_version"]}
        rows += [{k: (ran[k] if k in ran else r[k]) for k in SOLVE_COLUMNS} for r in cell["rows"]]
        epochs += [{k: e[k] for k in EPOCH_COLUMNS} for e in cell["epochs"]]
    write_csv(out / "solves.csv.gz", rows)
    write_csv(out / "instances.csv", epochs)
    return {"solve_rows": len(rows), "epochs": len(epochs)}


# -- re-planning ---------------------------------------------------------------------------------

REPLAN_COLUMNS = ["seed", "policy", "t_s", "intents", "airborne", "node", "airborne_inside",
                  "affected", "reach", "saved", "reach_delay_mean_s", "kept", "rerouted",
                  "retimed", "diverted", "cancelled", "contingency", "vertices", "edges",
                  "decision_s", "decision_cpu_s", "fallback", "losses", "incursions",
                  "approved", "requests", "updates_sha256", "wall_s"]


def replan_row(r: dict) -> dict:
    """One run's line of measure_replanning.py --out as a flat row (REPLAN_COLUMNS)."""
    flat = {**r, **r["kinds"]}
    return {k: flat.get(k) for k in REPLAN_COLUMNS}


def run_replanning(cfg: dict, out: Path, progress: bool = True) -> dict:
    """scripts/measure_replanning.py with the config's arguments, one process per seed (a seed
    that finished is kept in its JSON lines cell and not run again)."""
    from ..runner.sweep import code_version
    rp = cfg["replanning"]
    args = [str(a) for a in rp["args"]]
    seeds = list(range(int(rp.get("first_seed", 0)), int(rp.get("first_seed", 0)) + int(rp["seeds"])))
    cells = Path(cfg["cells"])
    cells.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in seeds:
        digest = hashlib.sha256(json.dumps([args, seed]).encode()).hexdigest()[:16]
        path = cells / f"replanning_s{seed}_{digest}_c{code_version()}.jsonl"
        if not path.exists():
            tmp = path.with_suffix(".part")
            tmp.unlink(missing_ok=True)
            cmd = [sys.executable, str(ROOT / "scripts" / "measure_replanning.py"), "--seeds", "1",
                   "--first-seed", str(seed), "--out", str(tmp), *args]
            run = subprocess.run(cmd, capture_output=not progress, text=True)
            if run.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)}: exit {run.returncode}")
            tmp.rename(path)
        rows += [replan_row(json.loads(line)) for line in path.read_text().splitlines() if line]
    write_csv(out / "replanning.csv", rows)
    (out / "replanning_args.json").write_text(json.dumps({"args": args, "seeds": seeds}) + "\n")
    return {"replanning_rows": len(rows)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="large_instances", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="config/large-instances.yaml")
    ap.add_argument("--stage", choices=STAGES + ("all",), default="all")
    ap.add_argument("--out", default=None, help="default: the config's out")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config)
    except ValueError as exc:
        print(f"large_instances: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out or cfg["out"])
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(cfg, indent=1, default=str) + "\n")
    info = {}
    if args.stage in ("solves", "all"):
        info.update(run_solves(cfg, out, not args.no_progress))
    if args.stage in ("replanning", "all"):
        info.update(run_replanning(cfg, out, not args.no_progress))
    from ..reports.large_instances_report import write_report
    write_report(out)
    print(f"large instances: {json.dumps(info)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
