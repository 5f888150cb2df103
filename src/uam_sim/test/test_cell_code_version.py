"""Cell keys carry the code version (issue 24): a cell computed by other run code is never reused
silently; it is reported as stale and left where it is."""

import json
from pathlib import Path

from uam_sim.studies.experiment import make_config, run_sweep
from uam_sim.runner.sweep import (cell_key, cell_params, cell_stem, code_version, files_version,
                           run_code_files, stale_cells)

NET = {"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}}


def small(out):
    return make_config(dict(network=NET, methods=["firstfit"], rates=[2], seeds=[0],
                            duration_s=120.0, out=str(out), workers=1, include_qpu=False,
                            tts={"enabled": False}))


def test_the_run_code_is_the_planner_solvers_and_simulator_not_studies_docs_or_tests():
    labels = [label for label, _p in run_code_files()]
    for must in ("uam_planner/planning.py", "uam_planner/first_fit.py", "uam_solvers/auto.py",
                 "uam_solvers/executor.py", "uam_contract/defaults.py", "uam_sim/runner/scenario.py",
                 "uam_sim/world/demand.py", "uam_sim/world/flights.py", "uam_sim/world/disturbance.py",
                 "requirements.txt"):
        assert must in labels, must
    for never in ("uam_sim/studies/decision_study.py", "uam_sim/reports/decision_report.py", "uam_sim/runner/sweep.py",
                  "uam_sim/reports/capacity_report.py", "uam_sim/reports/figures.py"):
        assert never not in labels, never
    assert not [x for x in labels if "/nodes/" in x or "/test/" in x or x.endswith(".md")]


def test_the_version_follows_the_bytes_of_every_file(tmp_path):
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("y = 2\n")
    v = files_version([("a.py", a), ("b.py", b)])
    assert v == files_version([("a.py", a), ("b.py", b)])
    b.write_text("y = 3\n")
    assert files_version([("a.py", a), ("b.py", b)]) != v
    assert len(code_version()) == 12


def test_a_cell_of_other_code_is_stale_reported_and_kept(tmp_path):
    cfg = small(tmp_path / "out")
    first = run_sweep(cfg, progress=False)
    assert len(first.computed) == 1 and first.stale == []
    key = cell_key(cell_params(cfg, "firstfit", 2, 0))
    assert key == f"{cell_stem(cell_params(cfg, 'firstfit', 2, 0))}_c{code_version()}"
    cells = Path(cfg.out) / "cells"
    cell = json.loads((cells / f"{key}.json").read_text())
    assert cell["code_version"] == code_version()
    # the same cell as another code version made it, and as a cell from before keys had one
    other = cell_key(cell_params(cfg, "firstfit", 2, 0), code="0123456789ab")
    legacy = cell_stem(cell_params(cfg, "firstfit", 2, 0))
    for name in (other, legacy):
        (cells / f"{name}.json").write_text(json.dumps({**cell, "key": name}))
    (cells / f"{key}.json").unlink()
    again = run_sweep(cfg, progress=False, compute=False)
    assert again.cells == [] and again.missing == [("firstfit", 2, 0)]
    assert sorted(p.name for p in again.stale) == sorted([f"{other}.json", f"{legacy}.json"])
    assert stale_cells(cells, key) == again.stale
    # computing it again writes the current version beside them; neither is deleted or reused
    third = run_sweep(cfg, progress=False)
    assert len(third.computed) == 1
    assert {p.name for p in cells.glob("*.json")} == {f"{key}.json", f"{other}.json", f"{legacy}.json"}
    assert run_sweep(cfg, progress=False, compute=False).stale == []
