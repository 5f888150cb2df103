"""Paper-shaped instance generators and the JSON Lines corpus format."""

import json

import numpy as np
import pytest

from uam_solvers.base import MwisInputError, MwisProblem
from uam_solvers.instances import (
    CORPUS_READERS,
    CorpusEntry,
    generate_corpus,
    generate_corpus_entries,
    large_instance,
    load_corpus,
    paper_instance,
    read_instances,
    save_corpus,
)


def _request_of(problem):
    owner = np.full(problem.n, -1)
    for r, g in enumerate(problem.groups):
        owner[g] = r
    return owner


def test_paper_instance_has_the_paper_structure():
    p = paper_instance(8, seed=3)
    assert p.n == 40
    assert len(p.groups) == 8
    for g in p.groups:
        assert len(g) == 5
        w = p.weights[g]
        assert w[0] == 1.0
        assert np.all(np.diff(w) < 0), "weights decrease along a request's candidates"
        assert np.all((w[1:] > 0) & (w[1:] < 1))
    owner = _request_of(p)
    # listed conflict edges join candidates of different requests only
    assert np.all(owner[p.edges[:, 0]] != owner[p.edges[:, 1]])
    assert p.m > 0
    # all_edges adds the 8 cliques of 5 (10 pairs each)
    assert len(p.all_edges()) == p.m + 8 * 10


def test_paper_instance_is_seeded():
    a, b, c = paper_instance(6, seed=11), paper_instance(6, seed=11), paper_instance(6, seed=12)
    assert np.array_equal(a.weights, b.weights) and np.array_equal(a.edges, b.edges)
    assert not (np.array_equal(a.weights, c.weights) and np.array_equal(a.edges, c.edges))


def test_paper_instance_discards_candidates_to_exact_size():
    p = paper_instance(4, seed=1, n_vertices=13)
    assert p.n == 13
    sizes = sorted(len(g) for g in p.groups if len(g))
    # every request keeps at least one candidate (singleton groups vanish from groups)
    assert sum(sizes) + (4 - len(p.groups)) == 13


@pytest.mark.parametrize("kwargs, field", [
    (dict(n_requests=0, seed=0), "n_requests"),
    (dict(n_requests=3, seed=0, conflict_prob=1.5), "conflict_prob"),
    (dict(n_requests=3, seed=0, n_vertices=16), "n_vertices"),
    (dict(n_requests=3, seed=0, n_vertices=2), "n_vertices"),
])
def test_paper_instance_rejects_bad_arguments(kwargs, field):
    with pytest.raises(MwisInputError, match=field):
        paper_instance(**kwargs)


def test_generate_corpus_spreads_sizes_over_the_range():
    problems = generate_corpus(92, min_vertices=5, max_vertices=50, seed=4)
    sizes = np.array([p.n for p in problems])
    assert sizes.min() == 5 and sizes.max() == 50
    counts = np.bincount(sizes)[5:51]
    assert np.all(counts == 2), "every size 5..50 appears equally often"
    again = generate_corpus(92, seed=4)
    assert all(np.array_equal(p.edges, q.edges) for p, q in zip(problems, again))


def test_large_instance_size_and_locality():
    p = large_instance(2003, seed=5)
    assert p.n == 2003
    assert len(p.groups) >= 2003 // 5
    # local interactions: average degree stays bounded (far below a dense graph)
    degree = 2 * len(p.all_edges()) / p.n
    assert 5 < degree < 60
    q = large_instance(2003, seed=5)
    assert np.array_equal(p.edges, q.edges)


def test_corpus_round_trip(tmp_path):
    entries = generate_corpus_entries(5, seed=1)
    entries[2] = CorpusEntry(entries[2].name, entries[2].problem, entries[2].source, optimum=2.5)
    path = save_corpus(tmp_path / "c.jsonl", entries)
    back = load_corpus(path)
    assert [e.name for e in back] == [e.name for e in entries]
    for a, b in zip(entries, back):
        assert np.array_equal(a.problem.weights, b.problem.weights)  # exact float round trip
        assert np.array_equal(a.problem.edges, b.problem.edges)
        assert [g.tolist() for g in a.problem.groups] == [g.tolist() for g in b.problem.groups]
        assert a.source == b.source
    assert back[2].optimum == 2.5 and back[0].optimum is None
    assert read_instances(path)[1].name == entries[1].name


def test_save_corpus_of_plain_problems_names_them(tmp_path):
    p = MwisProblem.from_arrays([1.0, 0.5], [[0, 1]])
    path = save_corpus(tmp_path / "p.jsonl", [p, p], optima=[1.0, None])
    lines = path.read_text().splitlines()
    assert len(lines) == 2
    record = json.loads(lines[0])
    assert record["name"] == "instance-0000" and record["optimum"] == 1.0
    assert "optimum" not in json.loads(lines[1])
    with pytest.raises(MwisInputError, match="unique"):
        save_corpus(tmp_path / "d.jsonl", [p, p], names=["a", "a"])


def test_load_corpus_errors_name_line_and_field(tmp_path):
    path = tmp_path / "bad.jsonl"
    good = '{"name":"ok","weights":[1,1],"edges":[[0,1]]}'
    path.write_text(good + "\n\n" + '{"name":"b","weights":[1,-2],"edges":[]}' + "\n")
    with pytest.raises(MwisInputError, match=r"bad.jsonl:3 \(b\).*weights\[1\]"):
        load_corpus(path)
    path.write_text('{"name":"c","weights":[1,1]}\n')
    with pytest.raises(MwisInputError, match="missing field 'edges'"):
        load_corpus(path)
    path.write_text(good + "\n" + good + "\n")
    with pytest.raises(MwisInputError, match="duplicate instance name 'ok'"):
        load_corpus(path)


def test_read_instances_refuses_unknown_suffix_and_names_the_known_ones(tmp_path):
    with pytest.raises(MwisInputError, match=r"'\.xyz'.*\.jsonl.*\.mcap"):
        read_instances(tmp_path / "run.xyz")
    assert {".jsonl", ".json", ".mcap"} <= set(CORPUS_READERS)
