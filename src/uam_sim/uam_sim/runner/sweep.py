"""The sweep of the study: cells (method, rate, seed) keyed by a hash of their parameters, run
in parallel over processes, written atomically and reused when finished (an interrupted sweep
resumes)."""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..world.demand import DemandSchedule, load_demand
from .experiment_config import BASELINES, ExperimentConfig, make_config, rate_label, resolve_path
from .files import write_json_atomic
from .network_spec import load_network_spec, network_identity
from .scenario import run_scenario

CELL_FORMAT = "uam-experiment-cell/1"


def cell_params(cfg: ExperimentConfig, method: str, rate, seed: int) -> dict:
    """Every parameter that affects a cell's result (its key is the hash of this)."""
    params = {"format": CELL_FORMAT, "method": method, "rate": rate_label(rate), "seed": int(seed),
              "network": network_identity(cfg.network)}
    for name in ("duration_s", "epoch_s", "interval_s", "window_s", "separation_m", "k",
                 "penalty_factor", "speed_mps", "corpus_max_vertices", "audit"):
        params[name] = getattr(cfg, name)
    if not cfg.paper_airspace:  # paper-mode cells keep the keys they had before airspace modes
        for name in ("separation_model", "vertical_separation_m", "departure_slot_s",
                     "climb_rate_mps", "descent_rate_mps"):
            params[name] = getattr(cfg, name)
    if method not in BASELINES:
        params["time_limit_s"] = cfg.time_limit_s
        params["solver_options"] = cfg.solver_options.get(method) or {}
    if cfg.airspace_mode != "paper":  # paper-mode keys stay as they were, so old cells resume
        params["airspace_mode"] = cfg.airspace_mode
    # only cells that leave the paper's objective, order or demand mix get the keys
    for name, default in (("objective", "paper"), ("baseline_order", "arrival"),
                          ("priority_share", 0.0), ("priority_class", 1), ("operators", []),
                          ("horizon_epochs", 1), ("commit_ahead", False), ("fair_window_s", 0.0), ("lead_time_s", 0.0),
                          ("operator_lead_times_s", []), ("metrics_warmup_s", 0.0),
                          # buffers, disturbances and conformance bounds
                          ("spatial_buffer_m", 0.0), ("temporal_buffer_s", 0.0),
                          ("disturbance", {}), ("conformance", {}), ("reaction", False),
                          ("reaction_period_s", 0.0), ("conflict_probe_s", 0.0),
                          ("conflict_probe_margin_m", 0.0)):
        if getattr(cfg, name) != default:
            params[name] = getattr(cfg, name)
    if cfg.disturbance:
        # safety gap: a disturbed run's planner sees the fleet and holds late flights
        # (results differ from cells run before it, which are not reused)
        params["planner_sees_fleet"] = 1
    if cfg.demand_file:
        params["demand"] = hashlib.sha256(resolve_path(cfg.demand_file).read_bytes()).hexdigest()
    if cfg.constraints_file:
        params["constraints"] = hashlib.sha256(resolve_path(cfg.constraints_file).read_bytes()).hexdigest()
    return params


#: the summary and epoch fields that are wall-clock measurements (the only ones allowed to differ
#: between two runs of one cell)
TIMING_FIELDS = frozenset({"wall_s", "real_time_factor", "solve_time_s", "planning_time_s",
                           "solve_time_mean_s", "solve_time_max_s", "solve_time_median_s",
                           "solve_time_p95_s"})
#: the cell fields that describe the machine during the run (its load, the run's CPU)
MACHINE_FIELDS = frozenset({"load", "cpu_s"})


def without_timing(cell: dict) -> dict:
    """A copy of a cell with its wall-clock fields set to None (to compare two runs of it)."""
    c = json.loads(json.dumps(cell))
    for k in MACHINE_FIELDS & set(c):
        c[k] = None
    for row in [c["summary"], *c["epochs"]]:
        for k in TIMING_FIELDS & set(row):
            row[k] = None
    return c


# -- the code version ------------------------------------------------------------------------------

#: packages whose every module (but ``nodes/`` and tests) is run code: the planner, the solvers
#: (backends are loaded by name, so an import walk would miss them) and the shared contract
RUN_PACKAGES = ("uam_contract", "uam_planner", "uam_solvers")
#: the simulator modules a run starts from; the run code of ``uam_sim`` is these and every
#: ``uam_sim`` module they import (anywhere in the file, function-level imports included), so
#: the studies, reports, figures and this sweep module are not part of it
RUN_ROOTS = ("uam_sim.runner.scenario", "uam_sim.world.demand", "uam_sim.runner.network_spec",
             "uam_sim.runner.experiment_config", "uam_sim.world.flights")
#: files beside the packages whose content decides what a run computes: the pinned libraries
PIN_FILES = ("requirements.txt",)


def _package_dir(name: str) -> Path:
    import importlib.util
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(f"code version: package {name!r} not found")
    return Path(list(spec.submodule_search_locations)[0])


def _imported_modules(path: Path, module: str, package: str) -> set:
    """Every ``package`` module ``path`` (module ``module``) imports, at any level of the file."""
    import ast
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    parts = module.split(".")
    is_pkg = path.name == "__init__.py"
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = parts[: len(parts) - node.level + (1 if is_pkg else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)  # "from . import x": x may be a module
    return {m for m in out if m == package or m.startswith(package + ".")}


def run_code_files() -> list:
    """[(label, path)] of the run code, sorted: every module of :data:`RUN_PACKAGES` but their
    ``nodes/`` and tests, the ``uam_sim`` modules reachable by imports from :data:`RUN_ROOTS`,
    and the pinned requirements (:data:`PIN_FILES`, where the checkout has them)."""
    files = {}
    for pkg in RUN_PACKAGES:
        root = _package_dir(pkg)
        for f in sorted(root.rglob("*.py")):
            rel = f.relative_to(root)
            if rel.parts[0] in ("nodes", "test", "tests"):
                continue
            files[f"{pkg}/{rel.as_posix()}"] = f
    sim = _package_dir("uam_sim")
    seen, todo = set(), list(RUN_ROOTS)
    while todo:
        mod = todo.pop()
        if mod in seen:
            continue
        rel = Path(*mod.split(".")[1:])
        f = sim / rel.with_suffix(".py") if mod != "uam_sim" else sim / "__init__.py"
        if not f.is_file():
            f = sim / rel / "__init__.py"
            if not f.is_file():
                continue  # "from .x import name": the name is not a module
        seen.add(mod)
        files[f"uam_sim/{f.relative_to(sim).as_posix()}"] = f
        todo.extend(_imported_modules(f, mod, "uam_sim") - seen)
    repo = sim.parents[2]
    for name in PIN_FILES:
        if (repo / name).is_file():
            files[name] = repo / name
    return sorted(files.items())


_CODE: list = []


def code_version() -> str:
    """A hash of the run code (:func:`run_code_files`: labels and contents), 12 hex digits.

    Part of every cell key, so a cell computed by other code is never reused silently (docs,
    tests, studies and reports are not run code, so editing them keeps the cells). Read once per
    process, at its first call, like :func:`_commit`: a cell's code is what the process loaded.
    """
    if not _CODE:
        _CODE.append(files_version(run_code_files()))
    return _CODE[0]


def pin_code_version(version: str) -> None:
    """Read and write cells as of run code ``version`` (12 hex digits) in this process instead of
    its own :func:`code_version`: for collecting into tables the cells that another checkout
    computed (a worktree at a study's frozen run code, so that the committed tables stay of one
    code version). Only for processes that compute no cell (``decision_study --stage tables
    --code-version V`` refuses any other stage): a cell computed here would carry a code version
    that is not its own. Raises ValueError naming the value."""
    if not (isinstance(version, str) and re.fullmatch(r"[0-9a-f]{12}", version)):
        raise ValueError(f"code version: {version!r} is not 12 lowercase hex digits "
                         f"(uam_sim.runner.sweep.code_version)")
    _CODE[:] = [version]


def files_version(files) -> str:
    """12 hex digits of the SHA-256 of [(label, path)]: each label and the file's bytes."""
    h = hashlib.sha256()
    for label, path in files:
        h.update(label.encode() + b"\0" + Path(path).read_bytes() + b"\0")
    return h.hexdigest()[:12]


def cell_stem(params: dict) -> str:
    """The part of a cell key its parameters decide: method, rate, seed and their hash."""
    digest = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]
    return f"{params['method']}_r{params['rate']}_s{params['seed']}_{digest}"


def cell_key(params: dict, code: str | None = None) -> str:
    """The cell's key (its file name): :func:`cell_stem` and the code version (default: this
    process's :func:`code_version`)."""
    return f"{cell_stem(params)}_c{code or code_version()}"


def stale_cells(cells_dir: Path, key: str) -> list:
    """Files in ``cells_dir`` with ``key``'s parameters but another code version (or none: cells
    from before keys carried it). They are never reused, nor deleted: the studies report them."""
    stem = key.rsplit("_c", 1)[0]
    out = [p for p in Path(cells_dir).glob(f"{stem}_c*.json") if p.stem != key]
    legacy = Path(cells_dir) / f"{stem}.json"
    return sorted(out + ([legacy] if legacy.is_file() else []))


def _read_cell(path: Path, key: str) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return data if data.get("key") == key else None


def run_cell(cfg_dict: dict, method: str, rate, seed: int, cells_dir: str) -> dict:
    """Run one cell and write it to ``cells_dir/<key>.json`` atomically; returns the cell dict.

    Top-level so a process pool can call it; loads (and caches) the network in the worker.
    """
    _commit()  # before the run, so an edit of the checkout during the run is not credited to it
    code_version()
    cfg = make_config(cfg_dict)
    params = cell_params(cfg, method, rate, seed)
    key = cell_key(params)
    net = load_network_spec(cfg.network)
    demand = None
    if cfg.demand_file:
        demand = DemandSchedule(load_demand(resolve_path(cfg.demand_file), net.aerodrome_ids),
                                cfg.interval_s)
    load0, cpu0 = os.getloadavg()[0], time.process_time()
    res = run_scenario(net, method, rate, seed, cfg.duration_s, cfg, demand=demand)
    cell = {"key": key, "params": params, "summary": res.summary, "epochs": res.epochs,
            "flights": res.flights, "audit": res.audit, "instances": res.instances,
            "rejections": res.rejections, "requests": res.requests,
            "code_version": code_version(),
            # the commit that ran this cell (on a Dask worker: that worker's checkout), for the
            # decision study's record; not part of the key
            "ran_at": _commit(),
            # the machine's 1-min load average before and after the run, and the run's CPU s:
            # solve limits are wall-clock, so a cell run on a loaded machine can fall back more
            # (the decision study's runs.csv carries them beside the fallbacks); not in the key
            "load": [round(load0, 2), round(os.getloadavg()[0], 2)],
            "cpu_s": round(time.process_time() - cpu0, 3)}
    write_json_atomic(Path(cells_dir) / f"{key}.json", cell)
    return cell


_COMMIT: list = []


def _commit() -> str:
    """The commit of the code this process runs: read once, at the first call after import
    (a cell's code is what the process loaded, not what the checkout holds when it ends)."""
    if not _COMMIT:
        from .machine import machine_info
        _COMMIT.append(str(machine_info().get("commit", "unknown")))
    return _COMMIT[0]


@dataclass
class SweepResult:
    """Cells in sweep order (method, rate, seed), and which were computed or reused."""

    config: ExperimentConfig
    cells: list
    computed: list
    reused: list
    wall_s: float
    missing: list = field(default_factory=list)
    #: files with a cell's parameters but another code version (not reused, not deleted)
    stale: list = field(default_factory=list)


def sweep_methods(cfg: ExperimentConfig) -> list:
    """The configured methods, plus "qpu" when include_qpu and the backend is available here."""
    methods = list(cfg.methods)
    if cfg.include_qpu and "qpu" not in methods:
        try:
            from uam_solvers.registry import get_backend
            ok, _ = get_backend("qpu").available()
        except Exception:  # an absent or broken optional backend just stays out of the sweep
            ok = False
        if ok:
            methods.append("qpu")
    return methods


def run_sweep(cfg: ExperimentConfig, progress: bool = True, compute: bool = True) -> SweepResult:
    """Run every missing cell, reuse the finished ones.

    Serial in this process when ``cfg.workers`` is 1 and no scheduler address is given; else on a
    Dask cluster (:mod:`uam_sim.runner.dask_cluster`): a LocalCluster of ``cfg.workers`` processes, or
    the cluster of ``cfg.scheduler``. Either way each cell is written as it finishes, by this
    process, so an interrupted sweep resumes.

    ``compute=False`` only collects the finished cells (the missing ones are listed in
    ``SweepResult.missing``), e.g. to report on a sweep that is still running.
    """
    t0 = time.perf_counter()
    out = Path(cfg.out)
    cells_dir = out / "cells"
    cells_dir.mkdir(parents=True, exist_ok=True)
    cfg_dict = asdict(cfg)
    grid = [(m, r, s) for m in sweep_methods(cfg) for r in cfg.rates for s in cfg.seeds]
    found: dict = {}
    todo = []
    stale = []
    for m, r, s in grid:
        key = cell_key(cell_params(cfg, m, r, s))
        cell = _read_cell(cells_dir / f"{key}.json", key)
        if cell is not None:
            found[(m, r, s)] = cell
        else:
            todo.append((m, r, s))
            stale += stale_cells(cells_dir, key)
    reused = list(found)
    # seeds outermost: an interrupted sweep has every (method, rate) for the first seeds
    seed_rank = {sd: i for i, sd in enumerate(cfg.seeds)}
    todo.sort(key=lambda c: seed_rank[c[2]])
    if not compute:
        return SweepResult(cfg, [found[c] for c in grid if c in found], [], reused,
                           time.perf_counter() - t0, missing=todo, stale=stale)
    bar = None
    if progress and todo:
        from tqdm import tqdm
        bar = tqdm(total=len(todo), desc="cells", unit="cell")
    remote = cfg.scheduler not in (None, "local")
    if not remote and (cfg.workers <= 1 or len(todo) <= 1):
        for m, r, s in todo:
            found[(m, r, s)] = run_cell(cfg_dict, m, r, s, str(cells_dir))
            if bar:
                bar.update(1)
    elif todo:
        from .dask_cluster import run_cells
        keys = {c: cell_key(cell_params(cfg, *c)) for c in todo}
        found.update(run_cells(cfg_dict, todo, keys, cells_dir, run_cell,
                               scheduler=cfg.scheduler or "local",
                               n_workers=min(cfg.workers, len(todo)),
                               on_done=(lambda _c, _cell: bar.update(1)) if bar else None))
    if bar:
        bar.close()
    return SweepResult(cfg, [found[c] for c in grid], list(todo), reused,
                       time.perf_counter() - t0, stale=stale)
