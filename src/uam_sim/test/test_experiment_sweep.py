"""uam_sim.studies.experiment: small sweeps (two rates, two methods, one seed, short runs)."""

from pathlib import Path

import pytest
import yaml

from uam_sim.world.demand import RequestGenerator
from uam_sim.studies.experiment import (ExperimentError, load_config, main, make_config, run_experiment,
                                run_scenario, run_sweep)
from uam_sim.runner.network_spec import load_network_spec
from uam_sim.runner.scenario import average_airborne
from uam_sim.runner.sweep import without_timing

REPO = Path(__file__).resolve().parents[3]
NET = {"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}}


def small(out, **kw):
    base = dict(network=NET, methods=["fifo", "greedy"], rates=[2, 6], seeds=[0],
                duration_s=300.0, out=str(out), workers=1, include_qpu=False,
                tts={"enabled": False})
    base.update(kw)
    return make_config(base)



@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    cfg = small(tmp_path_factory.mktemp("serial"))
    return cfg, run_sweep(cfg, progress=False)


def test_every_cell_is_present_and_consistent(serial):
    cfg, sweep = serial
    keys = [(c["summary"]["method"], c["summary"]["rate"], c["summary"]["seed"]) for c in sweep.cells]
    assert keys == [(m, r, 0) for m in ("fifo", "greedy") for r in (2, 6)]
    assert len(sweep.computed) == 4 and sweep.reused == []
    for c in sweep.cells:
        s = c["summary"]
        assert s["epochs"] == len(c["epochs"]) == 10          # t = 0, 30, ..., 270 < 300
        assert s["requests"] == 10 * s["rate"]
        assert s["approved"] == len(c["flights"]) == c["epochs"][-1]["approved_cum"]
        assert s["requests"] == s["approved"] + s["expired"] + s["pending_end"] + s["rejected"]
        assert s["approved"] > 0
        assert all(e["selected"] <= e["eligible"] for e in c["epochs"])
        assert (Path(cfg.out) / "cells" / f"{c['key']}.json").exists()


def test_methods_see_identical_demand(serial):
    cfg, sweep = serial
    net = load_network_spec(NET)
    for rate in (2, 6):
        gen = RequestGenerator(net.aerodrome_ids, rate, seed=0)
        issued = {r.request_id: r for i in range(10) for r in gen.requests_for_epoch(i)}
        for c in sweep.cells:
            if c["summary"]["rate"] != rate:
                continue
            for f in c["flights"]:
                r = issued[f["request_id"]]
                assert (f["origin"], f["destination"]) == (r.origin_id, r.destination_id)
                assert r.earliest_departure_s <= f["departure_s"] <= r.latest_departure_s


def test_audit_runs_and_finds_no_loss(serial):
    _, sweep = serial
    for c in sweep.cells:
        assert c["audit"]["losses"] == 0
        assert c["audit"]["min_separation_m"] is None or c["audit"]["min_separation_m"] >= 100.0
    assert sum(c["audit"]["pairs_checked"] for c in sweep.cells) > 0


@pytest.mark.slow  # not in `make test-fast`: a process pool
def test_parallel_equals_serial(serial, tmp_path):
    cfg, sweep = serial
    par = run_sweep(small(tmp_path, workers=2), progress=False)
    assert len(par.computed) == 4
    assert [without_timing(c) for c in par.cells] == [without_timing(c) for c in sweep.cells]


def test_resumed_run_recomputes_nothing(serial):
    cfg, sweep = serial
    cells = Path(cfg.out) / "cells"
    before = {p.name: p.stat().st_mtime_ns for p in cells.glob("*.json")}
    again = run_sweep(cfg, progress=False)
    assert again.computed == [] and len(again.reused) == 4
    assert {p.name: p.stat().st_mtime_ns for p in cells.glob("*.json")} == before
    assert [c["key"] for c in again.cells] == [c["key"] for c in sweep.cells]
    # a changed parameter changes the key: only the affected cells run again
    more = run_sweep(small(cfg.out, methods=["fifo", "greedy"], rates=[2, 6, 4]), progress=False)
    assert sorted(more.computed) == [("fifo", 4, 0), ("greedy", 4, 0)]
    longer = run_sweep(small(cfg.out, duration_s=330.0, methods=["fifo"], rates=[2]), progress=False)
    assert longer.computed == [("fifo", 2, 0)]
    # collecting without computing lists what is missing and runs nothing
    partial = run_sweep(small(cfg.out, rates=[2, 8]), progress=False, compute=False)
    assert partial.computed == [] and len(partial.cells) == 2
    assert sorted(partial.missing) == [("fifo", 8, 0), ("greedy", 8, 0)]


@pytest.mark.slow  # not in `make test-fast`: matplotlib figures, 4 s
def test_figures_report_and_tables_are_written(tmp_path):
    cfg = small(tmp_path, tts={"enabled": True, "instances": 6, "reads": 10, "repetitions": 2,
                               "backends": ["greedy", "exact", "sa"], "backend_instances": {"sa": 2}})
    out = run_experiment(cfg, progress=False)
    for name in ("cumulative_approved", "approved_per_rate", "aircraft_in_air", "mwis_size",
                 "solve_time"):
        p = tmp_path / "figures" / f"{name}.png"
        assert p.exists() and p.stat().st_size > 5000
    runs = (tmp_path / "runs.csv").read_text().splitlines()
    assert len(runs) == 1 + 4
    assert len((tmp_path / "epochs.csv").read_text().splitlines()) == 1 + 4 * 10
    report = (tmp_path / "REPORT.md").read_text()
    assert "Losses of separation: **0**" in report
    assert "figures/cumulative_approved.png" in report
    assert "Compared with the paper's statements" in report
    assert (tmp_path / "instances.jsonl").exists()
    tts = out["tts"]
    if tts["status"] == "ok":  # uam_solvers.tts present
        assert (tmp_path / "figures" / "tts.png").exists() and (tmp_path / "tts.csv").exists()
        per_backend = {b: sum(r["backend"] == b for r in tts["rows"]) for b in ("greedy", "exact", "sa")}
        assert per_backend == {"greedy": 6, "exact": 6, "sa": 2}
        # exact is the reference optimum: it reaches it in every run
        assert all(r["p_opt"] == 1.0 for r in tts["rows"] if r["backend"] == "exact")
        assert "TTS(0.99) per call and per read" in report
        again = run_experiment(cfg, progress=False, figures=False, report=False)
        assert again["sweep"].computed == [] and again["tts"].get("reused") is True
    from uam_solvers.instances import load_corpus
    corpus = load_corpus(tmp_path / "instances.jsonl")
    assert corpus and all(e.problem.n <= cfg.corpus_max_vertices for e in corpus)


def test_scenario_is_deterministic_and_same_seed_same_approvals():
    net = load_network_spec(NET)
    cfg = make_config({"audit": False})
    a = run_scenario(net, "greedy", 4, 1, 240.0, cfg)
    b = run_scenario(net, "greedy", 4, 1, 240.0, cfg)
    assert a.decisions() == b.decisions() and a.decisions()
    assert a.audit == {}


def test_average_airborne_is_integrated_exactly():
    # flights [0, 100], [50, 250] (clipped to 200), [300, 400] (outside) over 200 s
    assert average_airborne([0, 50, 300], [100, 250, 400], 200.0) == pytest.approx((100 + 150) / 200)
    assert average_airborne([], [], 10.0) == 0.0


def test_config_file_flags_and_errors(tmp_path):
    cfg = load_config(REPO / "config/experiment.yaml")
    assert cfg.rates == [1, 2, 4, 6, 8, 10, 15, 20] and cfg.seeds == [0, 1, 2, 3, 4]
    assert (cfg.duration_s, cfg.separation_m, cfg.k, cfg.epoch_s) == (3500.0, 100.0, 5, 30.0)
    assert cfg.methods == ["fifo", "firstfit", "greedy", "exact", "sa", "tabu", "qpu-emulator"]
    cfg = load_config(REPO / "config/experiment.yaml", rates="1,2.5", seeds="3,7", methods="fifo")
    assert (cfg.rates, cfg.seeds, cfg.methods) == ([1, 2.5], [3, 7], ["fifo"])
    with pytest.raises(ExperimentError, match="durations"):
        make_config({"durations": 5})
    with pytest.raises(ExperimentError, match="rates: item 'x'"):
        make_config({"rates": "1,x"})
    with pytest.raises(ExperimentError, match="duration_s"):
        make_config({"duration_s": -1})


def test_command_line_runs_a_small_sweep(tmp_path):
    conf = tmp_path / "exp.yaml"
    conf.write_text(yaml.safe_dump({"network": NET, "include_qpu": False, "seeds": 5}))
    rc = main(["--config", str(conf), "--rates", "2", "--methods", "fifo", "--seeds", "1",
               "--duration", "120", "--workers", "1", "--out", str(tmp_path / "res"),
               "--no-tts", "--no-progress"])
    assert rc == 0
    assert (tmp_path / "res" / "REPORT.md").exists()
    assert len(list((tmp_path / "res" / "cells").glob("*.json"))) == 1


def test_sweep_audit_hand_computed_closest_approach():
    from uam_planner.trajectory import Trajectory
    from uam_sim.audit.separation import sweep_audit
    import numpy as np
    # r1 east at 10 m/s, z = 100; r2 north at 10 m/s, z = 150, two segments; r3 5 km away.
    # |d|^2 = 2 (10 t - 500)^2 + 50^2: closest 50 m at t = 50 s.
    r1 = Trajectory(np.array([0.0, 100.0]), np.array([[0, 0, 100], [1000, 0, 100]], float))
    r2 = Trajectory(np.array([0.0, 50.0, 100.0]),
                    np.array([[500, -500, 150], [500, 0, 150], [500, 500, 150]], float))
    r3 = Trajectory(np.array([0.0, 100.0]), np.array([[0, 5000, 100], [1000, 5000, 100]], float))
    later = Trajectory(np.array([200.0, 300.0]), np.array([[0, 0, 100], [1000, 0, 100]], float))
    a = sweep_audit([r1, r2, r3, later], 100.0, ["r1", "r2", "r3", "r4"])
    assert a["min_separation_m"] == pytest.approx(50.0)
    assert a["min_time_s"] == pytest.approx(50.0)
    assert a["pair_of_min"] == ["r1", "r2"]
    assert a["losses"] == 1 and a["loss_pairs"][0][:2] == ["r1", "r2"]
    assert a["pairs_checked"] == 3          # r4 shares no time with the others
    assert sweep_audit([r1], 100.0)["min_separation_m"] is None


def test_sweep_audit_agrees_with_the_brute_force_audit():
    from uam_planner.audit import audit_flights
    from uam_sim.audit.separation import sweep_audit
    net = load_network_spec(NET)
    flown = []
    run_scenario(net, "greedy", 8, 3, 900.0, make_config({"audit": False}),
                 observer=lambda t, e, s, r, res: flown.extend(res.approved))
    trajs, labels = [f.trajectory for f in flown], [f.request_id for f in flown]
    assert len(trajs) > 30
    for sep in (100.0, 400.0):   # 400 m: many "losses", to compare the pair sets
        a = sweep_audit(trajs, sep, labels, chunk_pairs=5000, max_listed=10**6)
        b = audit_flights(trajs, sep, labels)
        assert a["min_separation_m"] == pytest.approx(b.min_separation_m, abs=1e-6)
        assert a["pairs_checked"] == b.pairs_checked
        near = lambda d: abs(d - sep) < 1e-6  # noqa: E731  (ties at the threshold: rounding)
        sa = {frozenset(x[:2]) for x in a["loss_pairs"] if not near(x[2])}
        sb = {frozenset(x[:2]) for x in b.losses if not near(x[2])}
        assert sa == sb
    assert sep == 400.0 and sa  # the comparison saw losses


def test_wrong_methods_network_and_misspelled_options_are_refused_naming_the_value(tmp_path, capsys):
    common = ["--rates", "2", "--seeds", "1", "--duration", "60", "--workers", "1",
              "--out", str(tmp_path / "res"), "--no-tts", "--no-progress"]
    # a misspelled backend was answered by greedy fallbacks and exited 0
    assert main(["--methods", "exat"] + common) == 2
    err = capsys.readouterr().err
    assert "methods: 'exat' is not a method" in err and "exact" in err
    # a missing network file ended in a traceback
    assert main(["--methods", "greedy", "--network", str(tmp_path / "nope.yaml")] + common) == 2
    assert "nope.yaml" in capsys.readouterr().err
    assert main(["--methods", "greedy", "--demand", str(tmp_path / "no-demand.yaml")] + common) == 2
    assert "demand_file: file" in capsys.readouterr().err
    # an abbreviation is not taken for the option it abbreviates
    with pytest.raises(SystemExit) as stop:
        main(["--methods", "greedy", "--dur", "60"] + common[:-6])
    assert stop.value.code == 2 and "--dur" in capsys.readouterr().err
    assert not (tmp_path / "res").exists()


def test_a_tts_study_with_nothing_to_measure_says_so_in_the_report(tmp_path, monkeypatch):
    monkeypatch.delenv("DWAVE_API_TOKEN", raising=False)
    from uam_solvers.registry import get_backend
    ok, _why = get_backend("qpu").available()
    if ok:
        pytest.skip("a D-Wave token is configured here: qpu would be measured")
    cfg = small(tmp_path, methods=["greedy"], rates=[6],
                tts={"enabled": True, "instances": 4, "reads": 10, "repetitions": 1, "backends": ["qpu"]})
    out = run_experiment(cfg, progress=False)
    assert out["tts"]["status"] == "skipped"
    assert out["tts"]["reason"].startswith("nothing to measure (unavailable backends: qpu")
    assert "Not run: nothing to measure (unavailable backends: qpu" in (tmp_path / "REPORT.md").read_text()
