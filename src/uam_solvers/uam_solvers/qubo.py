"""The QUBO form of MWIS, and the post-processing every annealing backend shares.

QUBO (design notes): minimise over x in {0, 1}^n

    E(x) = - sum_i w_i x_i + lambda * sum_{ij in E} x_i x_j

with E *all* conflict edges, the clique pairs of each request's group included, and lambda = 2 by
default (paper). For an independent set S, E(x_S) = -objective(S).

Why lambda > max_i w_i is enough (checked by brute force over every x on small graphs in
test_qubo_mwis.py):

* every single-flip local minimum of E is an independent set: if x_i = x_j = 1 on an edge ij,
  flipping x_i to 0 changes E by w_i - lambda * (number of selected neighbours of i)
  <= w_i - lambda < 0, so x was not a local minimum;
* it is also a *maximal* independent set when all weights are positive (adding a free vertex
  changes E by -w_i < 0);
* hence every global minimum is an independent set, and since E = -objective on independent
  sets, the QUBO minimum is exactly -MWIS. (lambda >= max w already suffices for the minimum
  *value*, but then ties may include infeasible states; the strict inequality removes them.)

Paper weights are w = d*/d <= 1, so lambda = 2 satisfies this with margin. For heavier weights
the backends still answer correctly because every read is repaired, and they report
``lambda_exceeds_max_weight = False`` in their statistics.

Post-processing of the sampler's reads (`refine_and_repair`): `steepest_descent` (one-flip
descent to a local minimum, vectorised over reads), then `repair` (drop the lighter end of each
violated edge, then add free vertices greedily by weight), then pick the best read. Statistics:
best objective, feasible fractions (raw reads and after descent, both before repair) and the
fraction of reads whose final answer reaches a known optimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import dimod
import numpy as np
import scipy.sparse as sp

from uam_solvers.base import MwisInputError, MwisProblem

DEFAULT_LAMBDA = 2.0

__all__ = [
    "DEFAULT_LAMBDA",
    "QuboArrays",
    "feasible_mask",
    "mwis_bqm",
    "mwis_qubo",
    "refine_and_repair",
    "repair",
    "steepest_descent",
]


@dataclass(frozen=True)
class QuboArrays:
    """A QUBO E(x) = offset + linear . x + 1/2 x^T coupling x over x in {0, 1}^n, as arrays.

    linear: (n,) float64. coupling: (n, n) symmetric CSR float64 with zero diagonal (the
    interaction J_ij of each pair appears at [i, j] and [j, i]).
    """

    linear: np.ndarray
    coupling: sp.csr_matrix
    offset: float = 0.0
    penalty: float | None = None  # lambda, when built by mwis_qubo

    @property
    def n(self) -> int:
        return int(self.linear.shape[0])

    def energies(self, samples) -> np.ndarray:
        """(R,) energies of (R, n) 0/1 samples (or one (n,) sample -> shape (1,)). O(R (n + m))."""
        x = np.atleast_2d(np.asarray(samples, dtype=np.float64))
        cx = np.asarray(self.coupling @ x.T).T
        return self.offset + x @ self.linear + 0.5 * np.einsum("rn,rn->r", x, cx)

    def to_bqm(self):
        """The same QUBO as a dimod BinaryQuadraticModel (BINARY), variables 0..n-1."""
        upper = sp.triu(self.coupling, k=1).tocoo()
        return dimod.BinaryQuadraticModel.from_numpy_vectors(
            self.linear, (upper.row, upper.col, upper.data), self.offset, dimod.BINARY)

    @classmethod
    def from_bqm(cls, bqm) -> "QuboArrays":
        """Arrays of a BINARY (or SPIN, converted) BQM whose variables are exactly 0..n-1."""
        if bqm.vartype is not dimod.BINARY:
            bqm = bqm.change_vartype(dimod.BINARY, inplace=False)
        n = bqm.num_variables
        if set(bqm.variables) != set(range(n)):
            raise MwisInputError("bqm: variables must be the integers 0..n-1")
        linear, (row, col, data), offset = bqm.to_numpy_vectors(variable_order=range(n))
        coupling = sp.coo_matrix((np.concatenate([data, data]),
                                  (np.concatenate([row, col]), np.concatenate([col, row]))),
                                 shape=(n, n)).tocsr()
        return cls(np.asarray(linear, dtype=np.float64), coupling, float(offset))


def mwis_qubo(problem: MwisProblem, lam: float = DEFAULT_LAMBDA) -> QuboArrays:
    """The MWIS QUBO of `problem` (groups' clique pairs included) as arrays. O(n + m)."""
    lam = float(lam)
    if not (np.isfinite(lam) and lam > 0):
        raise MwisInputError(f"lambda must be a finite number > 0, got {lam!r}")
    edges = np.asarray(problem.all_edges(), dtype=np.int64)
    n = problem.n
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    coupling = sp.csr_matrix((np.full(rows.shape[0], lam), (rows, cols)), shape=(n, n))
    return QuboArrays(-np.asarray(problem.weights, dtype=np.float64), coupling, 0.0, lam)


def mwis_bqm(problem: MwisProblem, lam: float = DEFAULT_LAMBDA):
    """The MWIS QUBO as a dimod.BinaryQuadraticModel (BINARY, variables 0..n-1)."""
    return mwis_qubo(problem, lam).to_bqm()


def steepest_descent(qubo: QuboArrays, samples) -> tuple[np.ndarray, np.ndarray]:
    """One-flip steepest descent of every read until no single flip lowers its energy.

    Each round computes, for every read, the energy change of flipping each variable, and flips
    every improving variable whose gain is the largest among its improving neighbours (ties: the
    lower index wins). Flipped variables of one round are never coupled, so their gains add up
    exactly; the read's steepest flip always belongs to the round, so a round gains at least as
    much as one classic steepest-descent step. Rounds repeat until no read has an improving flip:
    the result is a one-flip local minimum, deterministic, and energies never increase.
    Vectorised over reads and edges; a round costs O(R_active (n + m)); rounds are few (after
    annealing, usually 0 to 3; from random states, tens).

    Args:
        qubo: QuboArrays of the problem.
        samples: (R, n) or (n,) 0/1 array.

    Returns:
        (samples (R, n) int8, energies (R,) float64) after descent.
    """
    x = np.atleast_2d(np.asarray(samples)).astype(np.int8, copy=True)
    if x.shape[1] != qubo.n:
        raise MwisInputError(f"samples: expected {qubo.n} columns, got shape {x.shape}")
    h = qubo.linear
    c = qubo.coupling
    upper = sp.triu(c, k=1).tocoo()
    u, v = upper.row.astype(np.int64), upper.col.astype(np.int64)  # u < v
    field = np.asarray(c @ x.T.astype(np.float64)).T  # field[r, i] = sum_j C_ij x_rj
    # a flip must beat rounding noise to count as an improvement
    tol = 1e-12 * max(1.0, float(np.abs(h).max(initial=0.0)),
                      float(np.abs(c.data).max(initial=0.0)))
    active = np.arange(x.shape[0])
    while active.size:
        delta = (1 - 2 * x[active]) * (h + field[active])
        improving = delta < -tol
        keep = improving.any(axis=1)
        active, delta, improving = active[keep], delta[keep], improving[keep]
        if not active.size:
            break
        if u.size:
            du, dv = delta[:, u], delta[:, v]
            both = improving[:, u] & improving[:, v]
            # on a coupled pair of improving flips only the larger gain (lower index on ties) flips
            u_loses = both & (du > dv)
            v_loses = both & (du <= dv)
            rr, ee = np.nonzero(u_loses)
            improving[rr, u[ee]] = False
            rr, ee = np.nonzero(v_loses)
            improving[rr, v[ee]] = False
        flips = improving.astype(np.int8)
        sign = flips * (1 - 2 * x[active])  # +1 for 0 -> 1, -1 for 1 -> 0
        x[active] += sign
        field[active] += np.asarray(c @ sign.T.astype(np.float64)).T
    return x, qubo.energies(x)


def feasible_mask(samples, edges) -> np.ndarray:
    """(R,) bool: which 0/1 reads select no two ends of any edge in (m, 2) `edges`. O(R m)."""
    x = np.atleast_2d(np.asarray(samples)).astype(bool)
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if e.shape[0] == 0:
        return np.ones(x.shape[0], dtype=bool)
    return ~np.any(x[:, e[:, 0]] & x[:, e[:, 1]], axis=1)


def repair(samples, weights, edges) -> np.ndarray:
    """Turn every read into a maximal independent set, deterministically.

    1. For every violated edge (both ends selected) drop its lighter end (the higher index on
       equal weights); all violated edges of a read are handled at once, so each loses an end.
    2. Visit vertices by weight, heaviest first (lower index first on ties), and add each one
       that has no selected neighbour.

    A read that is already independent loses nothing (step 1 does nothing), so repair never lowers
    a feasible read's objective (weights are >= 0). Vectorised over reads.

    Args:
        samples: (R, n) or (n,) 0/1 array.
        weights: (n,) float64 >= 0.
        edges: (m, 2) all conflict edges (use MwisProblem.all_edges(), groups included).

    Returns:
        (R, n) int8 independent sets.

    Complexity: O(R m) for step 1; step 2 visits only vertices free in some read, each in
    O(R + degree).
    """
    x = np.atleast_2d(np.asarray(samples)).astype(np.int8, copy=True)
    w = np.asarray(weights, dtype=np.float64)
    n = w.shape[0]
    if x.shape[1] != n:
        raise MwisInputError(f"samples: expected {n} columns, got shape {x.shape}")
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if e.shape[0]:
        u, v = e[:, 0], e[:, 1]
        lighter = np.where(w[u] < w[v], u, np.where(w[v] < w[u], v, np.maximum(u, v)))
        rr, ee = np.nonzero(x[:, u].astype(bool) & x[:, v].astype(bool))
        x[rr, lighter[ee]] = 0
    adjacency = sp.csr_matrix((np.ones(2 * e.shape[0], dtype=np.int32),
                               (np.concatenate([e[:, 0], e[:, 1]]),
                                np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n))
    blocked = np.asarray(adjacency @ x.T.astype(np.int32)).T  # selected neighbours per vertex
    free = (x == 0) & (blocked == 0)
    candidates = np.flatnonzero(free.any(axis=0))
    order = candidates[np.lexsort((candidates, -w[candidates]))]
    indptr, indices = adjacency.indptr, adjacency.indices
    for vertex in order:
        rows = np.flatnonzero((x[:, vertex] == 0) & (blocked[:, vertex] == 0))
        if rows.size:
            x[rows, vertex] = 1
            neighbours = indices[indptr[vertex]:indptr[vertex + 1]]
            blocked[np.ix_(rows, neighbours)] += 1
    return x


def refine_and_repair(problem: MwisProblem, qubo: QuboArrays, raw_samples,
                      optimum: float | None = None, descend: bool = True
                      ) -> tuple[np.ndarray, dict]:
    """Descend, repair, and pick the best read; return (selected vertex indices, statistics).

    Args:
        problem: the MWIS problem the reads belong to (columns = vertices 0..n-1).
        qubo: its QUBO arrays (for the descent and energies).
        raw_samples: (R, n) 0/1 reads from a sampler, R >= 1.
        optimum: the known optimum of `problem`, for optimal_fraction (None: not reported).
        descend: run the steepest descent (True for every backend here).

    Returns:
        selected: int32 sorted indices of the best repaired read (ties: the first read).
        stats: reads, best_objective, mean_objective, feasible_fraction_raw (sampler reads that
        are independent sets), feasible_fraction (after descent, before repair), repaired_reads,
        energy_min/energy_mean (raw reads' QUBO energies), optimal_fraction (final answers that
        reach `optimum` within 1e-9 relative, only when optimum is given),
        lambda_exceeds_max_weight (when qubo.penalty is known).
    """
    raw = np.atleast_2d(np.asarray(raw_samples)).astype(np.int8)
    if raw.shape[0] == 0:
        raise MwisInputError("raw_samples: the sampler returned no reads")
    edges = problem.all_edges()
    raw_energy = qubo.energies(raw)
    feasible_raw = feasible_mask(raw, edges)
    descended = steepest_descent(qubo, raw)[0] if descend else raw
    feasible = feasible_mask(descended, edges)
    final = repair(descended, problem.weights, edges)
    objectives = final @ problem.weights
    best = int(np.argmax(objectives))
    stats = {
        "reads": int(raw.shape[0]),
        "best_objective": float(objectives[best]),
        "mean_objective": float(objectives.mean()),
        "feasible_fraction_raw": float(feasible_raw.mean()),
        "feasible_fraction": float(feasible.mean()),
        "repaired_reads": int((~feasible).sum()),
        "energy_min": float(raw_energy.min()),
        "energy_mean": float(raw_energy.mean()),
    }
    if qubo.penalty is not None:
        stats["lambda_exceeds_max_weight"] = bool(
            qubo.penalty > float(problem.weights.max(initial=0.0)))
    if optimum is not None:
        optimum = float(optimum)
        reached = objectives >= optimum - 1e-9 * max(1.0, abs(optimum))
        stats["optimal_fraction"] = float(reached.mean())
    selected = np.flatnonzero(final[best]).astype(np.int32)
    return selected, stats
