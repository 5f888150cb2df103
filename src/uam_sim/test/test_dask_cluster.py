"""The sweep's cells on a local multi-worker Dask cluster equal the serial run's; bad input named."""

from dataclasses import asdict
from pathlib import Path

import pytest

from uam_sim.runner.dask_cluster import DistributedError, run_cells, validate_scheduler
from uam_sim.studies.experiment import ExperimentError, make_config, run_sweep
from uam_sim.runner.sweep import cell_key, cell_params, run_cell, without_timing

NET = {"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}}


def small(out, **kw):
    base = dict(network=NET, methods=["fifo", "firstfit", "greedy"], rates=[2, 6], seeds=[0],
                duration_s=240.0, out=str(out), workers=1, include_qpu=False,
                tts={"enabled": False})
    base.update(kw)
    return make_config(base)



@pytest.mark.slow  # starts a 2-process LocalCluster (a few seconds on a quiet machine)
def test_local_cluster_gives_the_serial_cells_and_resumes(tmp_path):
    serial = run_sweep(small(tmp_path / "serial"), progress=False)
    cfg = small(tmp_path / "dask")
    todo = [(m, r, s) for m in cfg.methods for r in cfg.rates for s in cfg.seeds]
    keys = {c: cell_key(cell_params(cfg, *c)) for c in todo}
    done_order = []
    cells = run_cells(asdict(cfg), todo, keys, Path(cfg.out) / "cells", run_cell, scheduler="local",
                      n_workers=2, on_done=lambda c, _cell: done_order.append(c))
    assert sorted(done_order) == sorted(todo)
    assert [without_timing(cells[c]) for c in todo] == [without_timing(c) for c in serial.cells]
    # the driver wrote every cell: a sweep over the same directory resumes with nothing to do
    again = run_sweep(cfg, progress=False)
    assert again.computed == [] and len(again.reused) == len(todo)
    # a worker whose key differs (another commit / other files) is refused, naming the cell
    bad = dict(keys)
    bad[todo[0]] = "fifo_r2_s0_0000000000000000"
    with pytest.raises(DistributedError, match=r"cell \('fifo', 2, 0\): the worker computed key"):
        run_cells(asdict(cfg), todo[:1], bad, tmp_path / "bad", run_cell, scheduler="local",
                  n_workers=1)


@pytest.mark.slow  # a LocalCluster again, through run_sweep
def test_sweep_uses_the_cluster_when_asked_and_config_is_checked(tmp_path):
    serial = run_sweep(small(tmp_path / "serial", methods=["firstfit"], rates=[2, 4]), progress=False)
    local = run_sweep(small(tmp_path / "local", methods=["firstfit"], rates=[2, 4], scheduler="local",
                            workers=2), progress=False)
    assert len(local.computed) == 2
    assert [without_timing(c) for c in local.cells] == [without_timing(c) for c in serial.cells]
    with pytest.raises(ExperimentError, match="scheduler: 'host:8786'"):
        small(tmp_path, scheduler="host:8786")
    with pytest.raises(ExperimentError, match="airspace_mode: 'fast' is not one of"):
        small(tmp_path, airspace_mode="fast")


def test_scheduler_values_are_checked():
    assert validate_scheduler(None) is None
    assert validate_scheduler("local") == "local"
    assert validate_scheduler("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    for bad in ("", "10.0.0.5:8786", "http://host:8786", 5):
        with pytest.raises(ValueError, match="scheduler: "):
            validate_scheduler(bad)


def test_unreachable_scheduler_is_a_clear_error(tmp_path):
    cfg = small(tmp_path)
    c = ("fifo", 2, 0)
    # port 9 refuses: the client retries until its timeout, which is all that this wait is
    with pytest.raises(DistributedError, match="scheduler: cannot reach 'tcp://127.0.0.1:9'"):
        run_cells(asdict(cfg), [c], {c: cell_key(cell_params(cfg, *c))}, tmp_path / "cells",
                  run_cell, scheduler="tcp://127.0.0.1:9", connect_timeout_s=0.5)
