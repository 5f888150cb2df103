"""The sweep's cells on a Dask distributed cluster: one host's LocalCluster or many hosts.

    python -m uam_sim.experiment --config config/experiment.yaml --scheduler tcp://HOST:8786
    python -m uam_sim.experiment --config config/experiment.yaml --scheduler local --workers 4

Each cell is a pure function of its parameters (``uam_sim.runner.sweep.run_cell``), so cells can run
anywhere: a worker computes a cell in a scratch directory of its own and sends the cell back;
the *driver* (the process that runs the sweep) writes it to ``<out>/cells/<key>.json`` atomically
as each one finishes. So the workers need no shared file system and no ROS, only the project's
Python environment and a checkout of the same commit (for the network and demand files), and an
interrupted sweep resumes exactly as a local one: the finished cells are on the driver's disk.

The driver checks that the key a worker computed equals its own for that cell; a worker with a
different network file or demand file (another commit) would change the key, and the sweep stops
with an error naming the cell and both keys instead of mixing results.

``scheduler``: ``"local"`` starts a ``distributed.LocalCluster`` of ``n_workers`` processes with
one thread each (the cells are CPU-bound Python; threads would share one GIL), no dashboard (so
no port is taken), closed at the end; any other string is a scheduler address to connect to
(``tcp://HOST:8786``), whose workers are started separately (``dask worker tcp://HOST:8786
--nworkers N --nthreads 1``, see docs/dask.md).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable, Sequence

LOCAL = "local"


class DistributedError(RuntimeError):
    """A cluster problem: unreachable scheduler, a worker's key mismatch, a missing package."""


def validate_scheduler(value) -> str | None:
    """None, "local" or a ``tcp://``/``tls://``/``inproc://`` address; else a ValueError naming it."""
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"scheduler: {value!r} must be 'local' or an address like tcp://HOST:8786")
    v = value.strip()
    if v == LOCAL or v.split("://", 1)[0] in ("tcp", "tls", "inproc", "ucx", "ws", "wss") and "://" in v:
        return v
    raise ValueError(f"scheduler: {value!r} must be 'local' or an address like tcp://HOST:8786")


def compute_cell(cell_fn: Callable, cfg_dict: dict, method: str, rate, seed: int) -> dict:
    """Run ``cell_fn`` (``uam_sim.runner.sweep.run_cell``) for one cell on a worker in a scratch
    directory and return the cell dict (not kept there).

    Top-level so Dask pickles it (and ``cell_fn``) by reference; the worker imports the runner.
    """
    with tempfile.TemporaryDirectory(prefix="uam-cell-") as scratch:
        return cell_fn(cfg_dict, method, rate, seed, scratch)


def _client(scheduler: str, n_workers: int, connect_timeout_s: float = 30.0):
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pinned in requirements.txt; say how to get it
        raise DistributedError(f"the Dask scheduler needs the 'distributed' package ({exc}); "
                               f"run scripts/setup.sh") from exc
    if scheduler == LOCAL:
        cluster = LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        return Client(cluster), cluster
    try:
        return Client(scheduler, timeout=f"{float(connect_timeout_s)}s"), None
    except (OSError, TimeoutError) as exc:
        raise DistributedError(f"scheduler: cannot reach {scheduler!r} ({exc})") from exc


def run_cells(cfg_dict: dict, todo: Sequence[tuple], expected_keys: dict, cells_dir,
              cell_fn: Callable, scheduler: str = LOCAL, n_workers: int = 2,
              on_done: Callable[[tuple, dict], None] | None = None,
              connect_timeout_s: float = 30.0, cell_configs: dict | None = None) -> dict:
    """Run the cells ``todo`` [(method, rate, seed)] on a Dask cluster; return {cell: cell dict}.

    Args:
        cfg_dict: the sweep's ExperimentConfig as a dict (``dataclasses.asdict``).
        todo: cells to compute, in submission order (the runner puts seeds outermost): tuples
            ending in (method, rate, seed), e.g. (arm-and-mode index, method, rate, seed).
        expected_keys: cell -> the key the driver computed; a worker's must match.
        cells_dir: where the driver writes each finished cell (atomically, as it arrives).
        cell_fn: the cell runner, ``uam_sim.runner.sweep.run_cell(cfg_dict, method, rate, seed, dir)``
            (passed in so this module does not import the sweep that uses it).
        scheduler: "local" or a scheduler address.
        n_workers: processes of the LocalCluster (ignored for an address).
        on_done: called with (cell, cell dict) as each cell is written (progress bars).
        connect_timeout_s: how long to try to reach a scheduler address [s].
        cell_configs: cell -> its own config dict (a study of several sweeps in one pool);
            ``cfg_dict`` is used for cells not in it.
    Raises DistributedError on a key mismatch or an unreachable scheduler; a cell that raises
    on a worker re-raises here (the cells written before stay, so the sweep resumes).
    """
    from distributed import as_completed

    from .files import write_json_atomic

    scheduler = validate_scheduler(scheduler) or LOCAL
    cells_dir = Path(cells_dir)
    cells_dir.mkdir(parents=True, exist_ok=True)
    client, cluster = _client(scheduler, n_workers, connect_timeout_s)
    done: dict = {}
    try:
        futs = {}
        for c in todo:
            m, r, s = c[-3:]
            conf = cfg_dict if cell_configs is None or c not in cell_configs else cell_configs[c]
            # pure=False: never deduplicate or cache; each cell is computed once, as submitted
            f = client.submit(compute_cell, cell_fn, conf, m, r, s, pure=False,
                              key=f"cell-{expected_keys[c]}-{os.getpid()}")
            futs[f] = c
        for fut in as_completed(list(futs)):
            c = futs[fut]
            cell = fut.result()
            if cell.get("key") != expected_keys[c]:
                raise DistributedError(
                    f"cell {c}: the worker computed key {cell.get('key')!r}, the driver expects "
                    f"{expected_keys[c]!r}; the worker runs another commit or has other network "
                    f"or demand files (the cell key hashes them)")
            write_json_atomic(cells_dir / f"{cell['key']}.json", cell)
            done[c] = cell
            # written: let the worker drop its copy. A held result is lost when the nanny
            # restarts a worker (memory: a Monte-Carlo worker at 9.4 GiB) and then
            # computed again; 47 finished cells were, for nothing
            del futs[fut]
            fut.release()
            if on_done is not None:
                on_done(c, cell)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return done
