"""The study's analyses: hand-computed centrality, flight metrics, per-read TTS, warm-up; the
figures and report sections of a small sweep."""

import math
from pathlib import Path

import numpy as np
import pytest

from uam_planner.network import network_from_enu
from uam_sim.studies.experiment import make_config, run_experiment
from uam_sim.reports.report import report_from_tables
from uam_sim.reports.figures import (central_corridors, corridor_use_m, flight_metrics, per_read_tts,
                             warmup_time_s)


def path_network():
    """a - b - c - d on a line, 1 km apart; a and d are aerodromes."""
    return network_from_enu("path", ["a", "b", "c", "d"],
                            [(0, 0, 0), (1000, 0, 0), (2000, 0, 0), (3000, 0, 0)],
                            [True, False, False, True], [("a", "b"), ("b", "c"), ("c", "d")])


def test_central_corridor_of_a_path_is_the_middle_one():
    net = path_network()
    cent, top = central_corridors(net, share=0.10)
    # shortest paths through each corridor: a-b 3 pairs, b-c 4 pairs, c-d 3 pairs (of 6)
    mid = net.edge_index(net.node_index("b"), net.node_index("c"))
    assert top.sum() == 1 and top[mid]
    assert cent[mid] == pytest.approx(4 / 6) and sorted(cent)[:2] == pytest.approx([0.5, 0.5])


def test_flight_metrics_by_hand():
    net = path_network()
    _, top = central_corridors(net)
    flights = [  # a->d straight (3 km, 1 of it central), no delay
        {"route": "a b c d", "length_m": 3000.0, "weight": 1.0, "candidate_index": 0,
         "departure_s": 30.0, "earliest_departure_s": 30.0},
        # c->d (1 km, not central), weight 0.5 -> a 100 % detour, 60 s late
        {"route": "c d", "length_m": 1000.0, "weight": 0.5, "candidate_index": 1,
         "departure_s": 90.0, "earliest_departure_s": 30.0}]
    m = flight_metrics({"flights": flights}, net, top)
    assert m["route_length_mean_m"] == 2000.0 and m["detour_mean_pct"] == 50.0
    assert m["delay_mean_s"] == 30.0 and m["delayed_share"] == 0.5 and m["shortest_share"] == 0.5
    assert m["central_share"] == pytest.approx(1000 / 4000)
    assert corridor_use_m(net, flights).tolist() == [1000.0, 1000.0, 2000.0]
    assert corridor_use_m(net, []).tolist() == [0.0, 0.0, 0.0]


def test_corridor_use_adds_each_leg_in_the_flights_order_as_a_loop_would():
    """The vectorised sum is the loop over every leg of every route, to the last bit (lengths
    that do not add exactly: a corridor flown many times)."""
    from uam_planner.synthetic import generate_network

    net = generate_network(300, 12, seed=5)
    rng = np.random.default_rng(1)
    flights = []
    for _ in range(300):
        walk = [int(rng.integers(0, net.n_nodes))]
        for _ in range(int(rng.integers(1, 12))):
            walk.append(int(rng.choice(list(net.graph.neighbors(walk[-1])))))
        flights.append({"route": " ".join(net.node_ids[i] for i in walk)})
    loop = np.zeros(net.n_edges)
    for f in flights:
        idx = [net.node_index(x) for x in f["route"].split()]
        for a, b in zip(idx[:-1], idx[1:]):
            loop[net.edge_index(a, b)] += net.edge_length_m[net.edge_index(a, b)]
    assert corridor_use_m(net, flights).tobytes() == loop.tobytes()
    assert flight_metrics({"flights": []}) == {}


def test_per_read_tts_by_hand():
    # 100 reads in 0.1 s -> 1 ms per read; p_read 0.5 -> log(0.01)/log(0.5) = 6.6439 reads
    row = {"t_c_s": 0.1, "num_reads": 100, "read_opt_fraction": 0.5}
    assert per_read_tts(row) == pytest.approx(1e-3 * math.log(0.01) / math.log(0.5))
    assert per_read_tts({**row, "read_opt_fraction": 1.0}) == pytest.approx(1e-3)  # one read
    assert per_read_tts({**row, "read_opt_fraction": 0.995}) == pytest.approx(1e-3)
    assert per_read_tts({**row, "read_opt_fraction": 0.0}) is None  # never optimal
    assert per_read_tts({"t_c_s": 0.1, "num_reads": "", "read_opt_fraction": ""}) is None
    assert per_read_tts({**row, "tts99_per_read_s": 0.004}) == 0.004  # the TTS module's own value


def test_warmup_is_when_the_curve_reaches_90_percent_of_its_steady_level():
    t = np.arange(0, 3000, 30.0)
    active = np.minimum(t / 1200.0, 1.0) * 100.0  # linear ramp to 100 at 1200 s
    warm, steady = warmup_time_s(t, active)
    assert steady == 100.0
    assert 1050 <= warm <= 1110  # 90 on the ramp at 1080 s, smoothed over 5 epochs


@pytest.mark.slow  # ~10 figures: about 30 s of matplotlib layout on a quiet 2-core machine
def test_small_study_has_every_figure_and_paired_section(tmp_path):
    cfg = make_config(dict(network={"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}},
                           methods=["fifo", "firstfit", "greedy", "exact"], rates=[2, 6],
                           seeds=[0], duration_s=300.0, out=str(tmp_path), workers=1,
                           include_qpu=False, cumulative_rates=[2, 6],
                           tts={"enabled": True, "instances": 4, "reads": 10, "repetitions": 2,
                                "backends": ["exact", "sa"], "backend_instances": {}}))
    out = run_experiment(cfg, progress=False)
    for name in ("cumulative_approved", "approval_rate_vs_load", "active_over_time",
                 "delay_detour", "corridors_centrality", "mwis_size", "solve_time"):
        p = tmp_path / "figures" / f"{name}.png"
        assert p.exists() and p.stat().st_size > 5000, name
    report = (tmp_path / "REPORT.md").read_text()
    for section in ("## Departures from the paper", "### Each method against shortest FIFO",
                    "### Each MWIS method against first-fit", "### Greedy against exact",
                    "**Alternatives or optimisation?**", "## Corridor utilisation against centrality",
                    "## Route detour and departure delay", "## The expanded airspace"):
        assert section in report, section
    # the MWIS figure pools MWIS methods only: baselines' epochs are not in it
    n_mwis_instances = sum(1 for c in out["sweep"].cells if c["summary"]["method"] in ("greedy", "exact")
                           for e in c["epochs"] if e["vertices"] > 0)
    assert sum(r["instances"] for r in out["figures"]["mwis_size"]["table"]) == n_mwis_instances
    # every number of the report comes back from the tables (gzipped ones too)
    import gzip
    import shutil
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("runs.csv", "tts.csv", "report_inputs.json"):
        shutil.copy(tmp_path / name, copy / name)
    for name in ("epochs.csv", "flights.csv"):
        with open(tmp_path / name, "rb") as src, gzip.open(copy / f"{name}.gz", "wb") as dst:
            shutil.copyfileobj(src, dst)
    again = report_from_tables(copy)
    assert again.read_text() == report
    assert "TTS(0.99) per call and per read" in report and "Per read:" in report


@pytest.mark.slow  # about 15 s: every table of the committed paper study, the figures' tables
def test_the_committed_paper_report_is_its_generators_output(tmp_path):
    import shutil
    committed = Path(__file__).resolve().parents[3] / "docs" / "paper-study"
    copy = tmp_path / "paper-study"
    shutil.copytree(committed, copy, ignore=shutil.ignore_patterns("figures"))
    again = report_from_tables(copy, render=False).read_text()   # the images: the small study's test
    assert "## The paper's figures side by side" in again
    for fig in ("### Fig. 3", "### Fig. 4", "### Fig. 5", "### Fig. 6"):
        assert fig in again, fig
    assert again == (committed / "REPORT.md").read_text()


@pytest.mark.slow  # about 12 s: the committed load sweep's tables, the figures' tables
def test_the_committed_load_sweep_report_is_its_generators_output(tmp_path):
    import shutil
    committed = Path(__file__).resolve().parents[3] / "docs" / "load-sweep"
    copy = tmp_path / "load-sweep"
    shutil.copytree(committed, copy, ignore=shutil.ignore_patterns("figures"))
    again = report_from_tables(copy, render=False).read_text()
    assert "--config config/load-sweep.yaml --out results/load-sweep" in again   # its own command
    assert again == (committed / "REPORT.md").read_text()


@pytest.mark.slow  # 5-10 s each: every table of the study, the figures' tables, no image
@pytest.mark.parametrize("study", ["load-sweep-city", "load-sweep-paper"])
def test_the_other_committed_load_sweeps_rebuild_from_their_tables(tmp_path, study):
    import shutil
    committed = Path(__file__).resolve().parents[3] / "docs" / study
    copy = tmp_path / study
    shutil.copytree(committed, copy, ignore=shutil.ignore_patterns("figures"))
    again = report_from_tables(copy, render=False).read_text()
    assert f"--out results/{study}" in again   # its own command
    assert again == (committed / "REPORT.md").read_text()
    assert not list((copy / "figures").glob("*.png"))   # the tables only
