"""Time-to-solution formula and the TTS study command line."""

import csv
import json
import math

import numpy as np
import pytest

import uam_solvers.registry as registry
from uam_solvers.base import Backend, MwisInputError, MwisProblem, make_result
from uam_solvers.instances import CorpusEntry, load_corpus, paper_instance, save_corpus
from uam_solvers.qubo import feasible_mask
from uam_solvers.tts import CSV_COLUMNS, main, run_study, time_to_solution


def brute_force(problem):
    n = problem.n
    x = ((np.arange(2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)
    ok = feasible_mask(x, problem.all_edges())
    return float(np.where(ok, x @ problem.weights, -np.inf).max())


def test_tts_formula_hand_values():
    assert time_to_solution(0.02, 1.0) == (0.02, "optimal every run")
    # log(0.01) / log(0.5) = 6.6439 runs
    value, rule = time_to_solution(0.02, 0.5)
    assert rule == "formula" and value == pytest.approx(0.02 * 6.643856189774724)
    # p = 0.1: log(0.01) / log(0.9) = 43.71 runs
    assert time_to_solution(1.0, 0.1)[0] == pytest.approx(math.log(0.01) / math.log(0.9))
    assert time_to_solution(0.02, 0.0) == (None, "not reached")
    # a deterministic backend that misses the optimum counts 10 s, whatever its t_c
    assert time_to_solution(0.001, 0.0, deterministic=True) == (10.0, "deterministic miss penalty")
    assert time_to_solution(0.001, 1.0, deterministic=True) == (0.001, "optimal every run")
    # p_opt above the target: one run already suffices
    assert time_to_solution(0.3, 0.995) == (0.3, "single run suffices")
    with pytest.raises(MwisInputError, match="p_opt"):
        time_to_solution(0.1, 1.5)
    with pytest.raises(MwisInputError, match="t_c_s"):
        time_to_solution(-1.0, 0.5)


class _EmptyAnswer(Backend):
    """Test double: always answers the empty set (never optimal on a graph with weight)."""

    description = "test double"

    def __init__(self, name):
        self.name = name

    def solve(self, problem, *, time_limit_s, seed, options):
        return make_result(problem, [], proven_optimal=False, solve_time_s=0.0,
                           backend=self.name, stats={})


def test_study_separates_not_reached_from_deterministic_penalty(monkeypatch):
    real = registry.get_backend
    doubles = {"never-stochastic": _EmptyAnswer("never-stochastic"),
               "never-deterministic": _EmptyAnswer("never-deterministic")}
    monkeypatch.setattr(registry, "get_backend", lambda name: doubles.get(name) or real(name))
    problem = MwisProblem.from_arrays([0.6, 1.0, 0.7, 0.5], [[0, 1], [1, 2], [2, 3]])
    entries = [CorpusEntry("path", problem, optimum=1.5)]
    rows, skipped = run_study(entries, ["never-stochastic", "never-deterministic", "greedy"],
                              repetitions=2, deterministic={"never-deterministic", "greedy"},
                              log=lambda msg: None)
    assert skipped == []
    by_name = {r.backend: r for r in rows}
    assert by_name["never-stochastic"].tts99_s is None
    assert by_name["never-stochastic"].rule == "not reached"
    assert by_name["never-deterministic"].tts99_s == 10.0
    assert not by_name["never-deterministic"].reached
    # greedy (GWMIN) takes vertex 1 first here, then 3: the optimum {1, 3}
    assert by_name["greedy"].p_opt == 1.0 and by_name["greedy"].reached
    assert by_name["greedy"].tts99_s == pytest.approx(by_name["greedy"].t_c_s)


def test_cli_on_a_tiny_corpus_writes_csv_and_png(tmp_path, capsys):
    problems = [paper_instance(2, seed=s, n_vertices=8) for s in range(3)]
    corpus = save_corpus(tmp_path / "tiny.jsonl", problems, names=["a", "b", "c"],
                         optima=[brute_force(p) for p in problems])
    out = tmp_path / "out"
    assert main(["--corpus", str(corpus), "--backends", "greedy,sa,tabu", "--repetitions", "2",
                 "--num-reads", "5", "--out", str(out),
                 "--backend-options", '{"sa": {"num_sweeps": 50}}']) == 0
    with (out / "tts.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == CSV_COLUMNS
    assert len(rows) == 3 * 3
    assert {r["backend"] for r in rows} == {"greedy", "sa", "tabu"}
    for row in rows:
        assert row["repetitions"] == "2"
        assert 0.0 <= float(row["p_opt"]) <= 1.0
        assert float(row["t_c_s"]) > 0
        if row["backend"] in ("sa", "tabu"):
            assert row["num_reads"] == "5" and row["read_opt_fraction"] != ""
        if row["reached"] == "True":
            assert float(row["tts99_s"]) >= float(row["t_c_s"]) - 1e-12
    png = (out / "tts_boxplot.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    meta = json.loads((out / "tts_meta.json").read_text())
    assert meta["repetitions"] == 2 and meta["num_reads"] == 5
    assert meta["backend_options"] == {"sa": {"num_sweeps": 50}}
    printed = capsys.readouterr().out
    assert "median TTS" in printed and "greedy" in printed


def test_cli_generate_writes_a_corpus_with_proven_optima(tmp_path):
    corpus = tmp_path / "gen.jsonl"
    assert main(["--generate", "4", "--min-vertices", "5", "--max-vertices", "12",
                 "--corpus", str(corpus), "--out", str(tmp_path / "o"),
                 "--generate-only"]) == 0
    entries = load_corpus(corpus)
    assert [e.problem.n for e in sorted(entries, key=lambda e: e.problem.n)] == [5, 7, 9, 11]
    for entry in entries:
        assert entry.optimum == pytest.approx(brute_force(entry.problem))


# ---- issue 11: the paper's TTS, trial = one read -------------------------------------------

from uam_solvers.tts import reads_needed, wilson_interval  # noqa: E402


def test_wilson_interval_hand_values():
    # 10 of 1000: the textbook Wilson 95 % interval is [0.00544, 0.01831]
    lo, hi = wilson_interval(10, 1000)
    assert lo == pytest.approx(0.005441, abs=1e-5) and hi == pytest.approx(0.018309, abs=1e-5)
    lo, hi = wilson_interval(0, 100)
    assert lo == pytest.approx(0.0, abs=1e-12) and hi == pytest.approx(0.03699, abs=1e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_reads_needed_bounds_p_near_one_percent_within_a_factor_one_and_a_half():
    n = reads_needed(0.01, 1.5)
    lo, hi = wilson_interval(round(0.01 * n), n)
    assert lo >= 0.01 / 1.5 and hi <= 0.015
    lo, hi = wilson_interval(round(0.01 * (n // 2)), n // 2)
    assert not (lo >= 0.01 / 1.5 and hi <= 0.015)


class _OnePercentReads(Backend):
    """Every call's best read is optimal, but only 1 % of its reads are (an annealer)."""

    name = "one-percent"
    description = "test double"

    def solve(self, problem, *, time_limit_s, seed, options):
        return make_result(problem, [1, 3], proven_optimal=False, solve_time_s=0.0,
                           backend=self.name,
                           stats={"reads": options["num_reads"], "optimal_fraction": 0.01})


def test_per_read_p_opt_is_the_share_of_reads_not_of_calls(monkeypatch):
    real = registry.get_backend
    monkeypatch.setattr(registry, "get_backend",
                        lambda name: _OnePercentReads() if name == "one-percent" else real(name))
    monkeypatch.setattr("uam_solvers.tts.ANNEALING_BACKENDS", frozenset({"one-percent"}))
    problem = MwisProblem.from_arrays([0.6, 1.0, 0.7, 0.5], [[0, 1], [1, 2], [2, 3]])
    rows, _ = run_study([CorpusEntry("path", problem, optimum=1.5)], ["one-percent"],
                        repetitions=3, num_reads=1000, log=lambda msg: None)
    row = rows[0]
    assert row.p_opt == 1.0  # per call: every call's best read is optimal
    assert row.reads_total == 3000 and row.read_hits == 30 and row.p_read == pytest.approx(0.01)
    assert row.p_read_lo < 0.01 < row.p_read_hi and row.ci_within_factor is True
    assert row.trial_time == "read (wall time per read)"
    assert row.t_read_s == pytest.approx(row.t_c_s / 1000, rel=1e-6)
    # TTS per read: t_read log(0.01) / log(0.99) = 458.2 t_read; interval ordered
    assert row.tts99_read_s == pytest.approx(row.t_read_s * 458.21, rel=1e-3)
    assert row.tts99_read_lo_s < row.tts99_read_s < row.tts99_read_hi_s


class _NoOptimalRead(Backend):
    """An annealer whose reads never reach the optimum (three reads per call in the test)."""

    name = "no-optimal-read"
    description = "test double"

    def solve(self, problem, *, time_limit_s, seed, options):
        return make_result(problem, [0], proven_optimal=False, solve_time_s=0.0,
                           backend=self.name,
                           stats={"reads": options["num_reads"], "optimal_fraction": 0.0})


def test_no_optimal_read_in_a_few_reads_is_not_reached_instead_of_dividing_by_zero(monkeypatch):
    # 0 hits in 3 reads: the Wilson formula's lower bound came out as 5.6e-17, log(1 - 5.6e-17)
    # is 0.0 and the study stopped with ZeroDivisionError (the experiment's default run did).
    lo, hi = wilson_interval(0, 3)
    assert lo == 0.0 and 0.0 < hi < 1.0
    assert wilson_interval(3, 3)[1] == 1.0
    real = registry.get_backend
    monkeypatch.setattr(registry, "get_backend",
                        lambda name: _NoOptimalRead() if name == "no-optimal-read" else real(name))
    monkeypatch.setattr("uam_solvers.tts.ANNEALING_BACKENDS", frozenset({"no-optimal-read"}))
    problem = MwisProblem.from_arrays([0.6, 1.0, 0.7, 0.5], [[0, 1], [1, 2], [2, 3]])
    rows, _ = run_study([CorpusEntry("path", problem, optimum=1.5)], ["no-optimal-read"],
                        repetitions=1, num_reads=3, log=lambda msg: None)
    row = rows[0]
    assert row.read_hits == 0 and row.p_read == 0.0
    assert row.tts99_read_s is None and row.tts99_read_hi_s is None  # no hit: unbounded above
    assert row.tts99_read_lo_s > 0  # the interval's best case is still a number
