"""Sakai-Togasaki-Yamazaki greedy rules on graphs worked by hand."""
import numpy as np
import pytest

from uam_solvers.base import MwisProblem
from uam_solvers.greedy import GreedyBackend, greedy_mwis

PATH3 = ([2.0, 3.0, 2.0], [[0, 1], [1, 2]])
# Star: centre 0 (weight 5), leaves 1, 2, 3 (weight 2).
STAR = ([5.0, 2.0, 2.0, 2.0], [[0, 1], [0, 2], [0, 3]])


def test_gwmin_path_ties_go_to_lowest_index():
    # keys w/(d+1): 2/2, 3/3, 2/2 all tie -> vertex 0; then vertex 2 is alone.
    assert greedy_mwis(*PATH3, rule="gwmin").tolist() == [0, 2]


def test_gwmin2_path_prefers_heavy_middle():
    # keys w/w(N[v]): 2/5, 3/7, 2/5 -> vertex 1 wins and removes everything.
    assert greedy_mwis(*PATH3, rule="gwmin2").tolist() == [1]


def test_gwmax_path_deletes_heavy_degree_vertex():
    # keys w/(d(d+1)): 2/2, 3/6, 2/2 -> delete 1; no edges remain.
    assert greedy_mwis(*PATH3, rule="gwmax").tolist() == [0, 2]


def test_star_separates_the_rules():
    # GWMIN: centre 5/4 > leaves 2/2 -> {0}. GWMIN2: 5/11 > 2/7 -> {0}.
    assert greedy_mwis(*STAR, rule="gwmin").tolist() == [0]
    assert greedy_mwis(*STAR, rule="gwmin2").tolist() == [0]
    # GWMAX: centre 5/12 < leaves 2/2 -> delete centre -> {1, 2, 3} (weight 6, optimal).
    assert greedy_mwis(*STAR, rule="gwmax").tolist() == [1, 2, 3]


def test_gwmin_recomputes_degrees_in_remaining_graph():
    # 0-1, 1-2, 2-3, 3-4 with weights 1, 1.4, 1, 1, 3.
    # Initial keys: 0.5, 0.467, 0.333, 0.333, 1.5 -> take 4 (removes 3).
    # Remaining path 0-1-2: degrees now 1, 2, 1 -> keys 0.5, 0.467, 0.5 -> take 0 (removes 1),
    # then 2 is isolated -> take it.
    w = [1.0, 1.4, 1.0, 1.0, 3.0]
    e = [[0, 1], [1, 2], [2, 3], [3, 4]]
    assert greedy_mwis(w, e, "gwmin").tolist() == [0, 2, 4]


def test_gwmax_completion_pass_adds_free_deleted_vertices():
    # Path 0-1-2-3 weights 1, 4, 100, 100. Deletions: 0 (1/2), then 1 (4/2 < 100/6),
    # then tie 2 vs 3 at 100/2 -> delete 2. Remaining {3}; completion adds 1 (free) -> {1, 3}.
    w = [1.0, 4.0, 100.0, 100.0]
    e = [[0, 1], [1, 2], [2, 3]]
    assert greedy_mwis(w, e, "gwmax").tolist() == [1, 3]


@pytest.mark.parametrize("rule", ["gwmin", "gwmin2", "gwmax"])
def test_every_rule_returns_maximal_independent_sets_on_random_graphs(rule):
    rng = np.random.default_rng(7)
    for _ in range(30):
        n = int(rng.integers(1, 30))
        e = rng.integers(0, n, size=(int(rng.integers(0, 3 * n)), 2))
        e = e[e[:, 0] != e[:, 1]]
        w = rng.uniform(0, 1, n)
        w[rng.random(n) < 0.1] = 0.0
        p = MwisProblem.from_arrays(w, e)
        sel = greedy_mwis(w, e, rule)
        assert p.is_independent(sel)
        chosen = np.zeros(n, bool)
        chosen[sel] = True
        blocked = chosen.copy()
        for u, v in p.all_edges().tolist():
            blocked[u] |= chosen[v]
            blocked[v] |= chosen[u]
        assert blocked.all(), "every vertex is selected or has a selected neighbour"


def test_greedy_backend_uses_groups_and_reports_rule():
    p = MwisProblem.from_arrays([1.0, 0.9, 0.8], [], groups=[[0, 1, 2]])
    r = GreedyBackend().solve(p, time_limit_s=1.0, seed=0, options={"rule": "gwmin2"})
    assert r.selected.tolist() == [0] and r.objective == 1.0 and r.backend == "greedy"
    assert r.stats["rule"] == "gwmin2" and not r.proven_optimal


def test_unknown_rule_and_option_are_refused():
    with pytest.raises(ValueError, match="rule: 'best'"):
        greedy_mwis([1.0], [], "best")
    p = MwisProblem.from_arrays([1.0], [])
    with pytest.raises(ValueError, match="unknown option"):
        GreedyBackend().solve(p, time_limit_s=1.0, seed=0, options={"rules": "gwmin"})
