"""The capacity study (uam_sim.studies.capacity_study / capacity_report): arms x airspace modes run as the
paper study's cells, one pool for all of them, tables and a report computed from the tables."""


import pytest
import yaml

from uam_sim.reports.capacity_report import write_capacity_report
from uam_sim.studies.capacity_study import load_capacity_config, run_capacity_study
from uam_sim.runner.experiment_config import ExperimentError
from uam_sim.runner.sweep import without_timing




def write(tmp_path, **over):
    data = {"base": {"duration_s": 150.0, "seeds": 2, "time_limit_s": 0.5, "corpus_max_vertices": 0,
                     "include_qpu": False},
            "arms": [{"name": "sg", "network": "config/networks/singapore.yaml",
                      "modes": ["paper", "both"], "methods": ["fifo", "firstfit", "greedy"],
                      "rates": [6]}],
            "instances": {"source": {"arm": "sg", "mode": "both", "method": "greedy", "rate": 6,
                                     "seed": 0},
                          "bins": [1, 64, 4096], "per_bin": 1, "backends": ["greedy", "auto"],
                          "time_limit_s": 0.5, "best_known_limit_s": 1.0}}
    data.update(over)
    p = tmp_path / "capacity.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def test_bad_study_files_are_refused_naming_the_field(tmp_path):
    arm = {"name": "a", "network": "config/networks/singapore.yaml", "modes": ["paper"],
           "methods": ["greedy"], "rates": [2]}
    for arms, msg in (([{**arm, "modes": ["wide"]}], r"arms\[0\]\.modes\[0\]: 'wide' is not one of 'paper', 'slots'"),
                      ([{**arm, "colour": 1}], r"arms\[0\]\.colour: unknown field \(value 1; known: methods, modes, name"),
                      ([arm, arm], r"arms\[1\].name: 'a' is used twice"),
                      ([{k: v for k, v in arm.items() if k != "rates"}], r"arms\[0\].rates: missing"),
                      ([{**arm, "rates": [-1]}], r"arms\[0\] \(a, mode paper\): rates: item -1")):
        with pytest.raises(ExperimentError, match=msg):
            load_capacity_config(write(tmp_path, arms=arms))
    with pytest.raises(ExperimentError, match="base.network: 'x.yaml' is set per arm"):
        load_capacity_config(write(tmp_path, base={"network": "x.yaml"}))


@pytest.mark.slow  # two small sweeps (serial and a 2-process LocalCluster) and the instance study
def test_the_study_runs_in_one_pool_resumes_and_reports_from_its_tables(tmp_path):
    serial = run_capacity_study(load_capacity_config(write(tmp_path), out=str(tmp_path / "serial"),
                                                     workers=1), progress=False)
    pooled = run_capacity_study(load_capacity_config(write(tmp_path), out=str(tmp_path / "pool"),
                                                     workers=2), progress=False, instances=False)
    cells = lambda res: [without_timing(c) for _a, _m, sw in res["results"] for c in sw.cells]  # noqa: E731
    assert len(cells(serial)) == 2 * 3 * 2 and cells(pooled) == cells(serial)
    runs = serial["tables"]["runs"]
    assert {r["mode"] for r in runs} == {"paper", "both"}
    assert {r["network_flown"] for r in runs} == {"config/networks/singapore.yaml",
                                                  "config/networks/singapore-layered.yaml"}
    assert all(r["losses"] == 0 for r in runs)
    # every backend of the instance study on the same sampled instances, gaps against the best
    inst = serial["instances"]
    assert inst and {r["backend"] for r in inst} == {"greedy", "auto"}
    assert all(r["objective"] <= r["best_known"] + 1e-9 and r["gap_pct"] >= 0 for r in inst)
    # resumes: nothing computed again
    again = run_capacity_study(load_capacity_config(write(tmp_path), out=str(tmp_path / "serial"),
                                                    workers=1), progress=False, instances=False)
    assert sum(len(sw.computed) for _a, _m, sw in again["results"]) == 0
    # the report comes back identical from the tables alone, with its paired comparisons
    d = tmp_path / "serial"
    first = (d / "REPORT.md").read_text()
    write_capacity_report(d)
    assert (d / "REPORT.md").read_text() == first
    assert "| sg | both | 6 | greedy - firstfit |" in first and "0 losses of separation" in first
    for fig in ("approvals_by_mode", "approval_rate_vs_load", "mwis_variables", "active_over_time",
                "delay", "solve_time_gap_vs_size"):
        assert (d / "figures" / f"{fig}.png").stat().st_size > 5000


def test_the_auto_both_file_is_the_main_study_restricted_to_auto_in_both():
    # config/capacity-study-auto-both.yaml (issue 20's re-run): the same base and, for each of
    # its arms, the main study's network and rates with only method auto in mode "both"
    main = load_capacity_config("config/capacity-study.yaml")
    sub = load_capacity_config("config/capacity-study-auto-both.yaml")
    assert sub.base == main.base
    arms = {a.name: a for a in main.arms}
    assert [a.name for a in sub.arms] == ["singapore", "singapore-below-knee", "city"]
    for a in sub.arms:
        assert a.modes == ["both"] and a.methods == ["auto"]
        assert "both" in arms[a.name].modes and "auto" in arms[a.name].methods
        assert a.network == arms[a.name].network and a.rates == arms[a.name].rates
    combos = sub.combos()
    assert [(a.name, m) for a, m, _cfg in combos] == [("singapore", "both"),
                                                      ("singapore-below-knee", "both"),
                                                      ("city", "both")]


def test_the_approval_share_figure_gives_auto_firstfit_and_fifo_their_own_markers(tmp_path, monkeypatch):
    """One mode's auto, first-fit and FIFO curves shared the mode's marker (the colour already says
    the mode): each method now keeps its own marker, as in the other figures."""
    import pandas as pd

    from uam_sim.reports import capacity_report

    seen = {}
    monkeypatch.setattr(capacity_report, "save_figure", lambda fig, path: seen.setdefault("fig", fig))
    runs = pd.DataFrame([{"network": "n", "mode": mode, "method": m, "rate": r, "approval_rate": 0.5}
                         for mode in ("paper", "both") for m in ("auto", "firstfit", "fifo") for r in (10, 20)])
    capacity_report.approval_share_figure(runs, tmp_path / "share.png")
    lines = seen["fig"].axes[0].get_lines()
    marker = {line.get_label(): line.get_marker() for line in lines}
    assert len({marker[f"paper {m}"] for m in ("auto", "firstfit", "fifo")}) == 3, marker
    assert marker["paper auto"] == marker["both auto"], marker  # the method's, whatever the mode
