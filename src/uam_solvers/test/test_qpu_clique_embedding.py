"""qpu-emulator's decomposition embeds every subproblem with one K_30 clique embedding
(minorminer busclique) instead of a minorminer search per subproblem."""

from uam_solvers.instances import large_instance
from uam_solvers.qpu import QPU_SUBPROBLEM_SIZE, QpuEmulatorBackend, _emulator_sampler, clique_embedding


def test_clique_embedding_is_a_valid_minor_of_the_target_graph():
    child = _emulator_sampler()
    emb = clique_embedding(child, QPU_SUBPROBLEM_SIZE)
    assert emb is not None and sorted(emb) == list(range(QPU_SUBPROBLEM_SIZE))
    qubits = [q for chain in emb.values() for q in chain]
    assert len(qubits) == len(set(qubits))  # chains are disjoint
    nodes = set(child.nodelist)
    edges = {(min(a, b), max(a, b)) for a, b in child.edgelist}
    assert set(qubits) <= nodes

    def connected(a, b):
        return any((min(x, y), max(x, y)) in edges for x in a for y in b)

    for i in range(QPU_SUBPROBLEM_SIZE):
        chain = emb[i]
        # a chain is connected: grow it from its first qubit along couplers
        reached, frontier = {chain[0]}, [chain[0]]
        while frontier:
            q = frontier.pop()
            for r in chain:
                if r not in reached and (min(q, r), max(q, r)) in edges:
                    reached.add(r)
                    frontier.append(r)
        assert reached == set(chain), i
        for j in range(i + 1, QPU_SUBPROBLEM_SIZE):
            assert connected(chain, emb[j]), (i, j)
    assert clique_embedding(child, QPU_SUBPROBLEM_SIZE) is emb  # cached per child


def test_decomposed_emulator_uses_the_clique_embedding():
    problem = large_instance(6000, seed=2)  # more vertices than qubits: decomposed
    r = QpuEmulatorBackend().solve(problem, time_limit_s=2.0, seed=0,
                                   options={"num_sweeps": 100})
    assert r.stats["decomposed"] is True and r.stats["clique_embedding"] == 1
    assert r.stats["embedding_failures"] == 0 and r.stats["subproblems"] >= 1
    assert problem.is_independent(r.selected)
    assert r.objective >= r.stats["initial_objective"] - 1e-9
