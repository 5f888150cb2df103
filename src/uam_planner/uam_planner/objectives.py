"""What the planner optimises: the vertex weights of one epoch's conflict graph, per objective.

The MWIS maximises the sum of the selected vertices' weights, so an objective is a weight per
candidate (docs/objectives.md has the formula, the reason and a hand-computed example of each):

- ``paper``: the paper's weights, unchanged (w = d*/d, or T*/(T + delay) with levels or slots).
- ``count``: approvals first, then the least added delay and detour, lexicographic:
  w = B + q with q = Q - c (c the candidate's added delay + detour in whole steps of ``step_s``
  seconds, Q = max c + 1) and B = m Q + 1 > any sum of q (one vertex per request, m requests).
- ``delay``: the delay (counted from the earliest departure) an approval saves against not
  approving now: a request that can wait would depart at the next epoch at the earliest; one
  whose window closes before the next epoch would be refused, which counts as a delay of
  ``REFUSAL_EPOCHS`` epochs beyond its window (its urgency).
- ``priority``: integer classes (ASTM F3548 style): w = P_class B + q, with the class values
  P_0 = 1, P_r = 1 + sum over the requests of lower classes of their P, so one flight of a class
  outweighs every flight of all lower classes together; inside a class, as ``count``.
- ``fair``: proportional fairness between operators (Kelly 1998; alpha-fair with alpha = 1, Mo and
  Walrand 2000), re-weighted between epochs from the running shares: w = phi_o B + q with
  phi_o = round(F (n_o + 1) / (a_o + 1)) (n_o requests decided so far, a_o approved), the
  gradient of sum_o n_o log(a_o / n_o); clipped to [F, F * FAIR_MAX_RATIO].

Every objective but ``paper`` gives whole-number weights no larger than ``w_max`` (default
:data:`W_MAX`, the integer backends' resolution: CP-SAT and CHILS 10^6, KaMIS
min(10^6, (2^31 - 1) // n)), which ``uam_solvers.base.integer_weights`` passes on exactly, so an
exact backend's optimum is the objective's optimum. The bound is kept by coarsening the secondary
term only (``step_s`` grows from 1 s; at worst q = 0, the primary term alone); the primary term
(count, class, operator factor) is never rounded. Only priority classes can outgrow ``w_max`` by
themselves (many classes with many requests each): then the class weights are kept exact
(float64 holds whole numbers below 2^53 exactly, which greedy and the float backends use), the
integer backends round them (reported by ``EpochWeights.exact_for_integer_backends``), and
beyond 2^53 :class:`ObjectiveRangeError` is raised naming the counts.

**A registry** (:func:`register_objective`): each objective is a name, a one-line summary and a
weight function of the epoch (:class:`WeightContext` -> :class:`EpochWeights`); the planner's
``objective`` parameter, the runner's ``--objective``, run_fleet.sh's check and the planner's
configuration all read it (:func:`objective_names`, :func:`check_objective`), so a new objective
is one registered function (docs/extending.md). ``python -m uam_planner.objectives`` lists them.

Pure functions of the epoch's candidates and requests (and the running shares for ``fair``):
no wall time, no randomness. No rclpy.
"""

from __future__ import annotations

import re
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

#: integer weight bound: the integer backends' resolution (uam_solvers CP-SAT, CHILS; KaMIS up
#: to 2,147 vertices)
W_MAX = 10**6
#: largest whole number float64 holds exactly
FLOAT_EXACT = 2**53
#: ``delay``: a refused request counts as departing this many epochs after its window closed
REFUSAL_EPOCHS = 2
#: ``fair``: resolution F of the operator factor, and its largest ratio (an operator far behind
#: counts at most this many times one that is served in full)
FAIR_RESOLUTION = 10
FAIR_MAX_RATIO = 10
#: largest priority class a request may carry (uint8 on the wire)
MAX_PRIORITY = 255


class ObjectiveRangeError(ValueError):
    """The objective's exact weights do not fit float64's whole numbers (names the counts)."""


@dataclass(frozen=True)
class WeightContext:
    """What an objective's weight function sees of one epoch: its time and length [s], the
    eligible requests (``req_of[v]`` indexes them), per candidate its departure and flight time
    [s] and the paper's weight, the running operator shares (``fair``) and the weight bound."""

    t_s: float
    epoch_s: float
    requests: Sequence
    req_of: Any
    departure_s: Any
    duration_s: Any
    paper_weights: Any
    shares: Any
    w_max: int


@dataclass(frozen=True)
class Objective:
    """One registered objective: its name, a one-line summary (help texts) and its weights."""

    name: str
    summary: str
    weights: Callable[[WeightContext], "EpochWeights"]


_REGISTRY: dict[str, Objective] = {}
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")


def register_objective(name: str, summary: str, weights: Callable[[WeightContext], "EpochWeights"],
                       replace: bool = False) -> Objective:
    """Add an objective (ValueError naming the field for a bad name, a taken one, or a weight
    function that is not callable). Its weights must be finite and positive, one per candidate."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"objective name: {name!r} is not 1 to 32 lower-case letters, digits or '_'")
    if name in _REGISTRY and not replace:
        raise ValueError(f"objective name: {name!r} is already registered")
    if not callable(weights):
        raise ValueError(f"objective {name!r}: weights {weights!r} is not callable")
    _REGISTRY[name] = Objective(name, str(summary), weights)
    return _REGISTRY[name]


def unregister_objective(name: str) -> None:
    """Remove a registered objective (a test's own)."""
    _REGISTRY.pop(name, None)


def objective_names() -> tuple:
    """The registered objectives, in the order registered (the built-in ones first)."""
    return tuple(_REGISTRY)


def objective_problem(name) -> str:
    """Why ``name`` is not a registered objective ('' when it is): the parameter rule."""
    if not isinstance(name, str) or name not in _REGISTRY:
        return f"{name!r} is not an objective; known: {', '.join(_REGISTRY)} (uam_planner.objectives)"
    return ""


def check_objective(name) -> str:
    """``name`` if it is an objective, else ValueError naming the value and the choices."""
    problem = objective_problem(name)
    if problem:
        raise ValueError(f"objective: {problem}")
    return name


def check_priority(value) -> str | None:
    """Why ``value`` is not a priority class (an integer in [0, MAX_PRIORITY]), or None."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
            or not 0 <= int(value) <= MAX_PRIORITY:
        return f"priority: {value!r} is not an integer in [0, {MAX_PRIORITY}]"
    return None


def operator_of(request) -> str:
    """The operator of a request: its ``operator_id``, else the scope of an operator-scoped id
    ``operator/request`` (the planner node's keys), else ''."""
    op = getattr(request, "operator_id", "") or ""
    if op:
        return op
    rid = str(getattr(request, "request_id", ""))
    return rid.partition("/")[0] if "/" in rid else ""


@dataclass
class OperatorShares:
    """Running counts per operator for ``fair``: requests decided (approved or expired) and
    approved so far.

    The Planner counts both when an epoch is committed (a request filed far ahead counts only
    once it had its chance); the weights of an epoch read the counts as they were when it was
    prepared.

    ``window_s`` > 0 (``PlanningConfig.fair_window_s``): a sliding window of the run; only the
    decisions of epochs at times tau >= t - window_s count at the epoch at t (``record`` keeps
    each epoch's decisions with its time, ``advance(t)`` drops the older ones). 0: the whole run.
    """

    requested: Counter = field(default_factory=Counter)
    approved: Counter = field(default_factory=Counter)
    window_s: float = 0.0
    _events: deque = field(default_factory=deque, repr=False)

    def record(self, t_s: float, approved: Sequence[str], expired: Sequence[str]) -> None:
        """Count the operators of one epoch's approvals and expiries, decided at ``t_s``."""
        approved, expired = list(approved), list(expired)
        self.approved.update(approved)
        self.requested.update(approved)
        self.requested.update(expired)
        if self.window_s > 0.0:
            self._events.append((float(t_s), approved, expired))

    def advance(self, t_s: float) -> None:
        """With a window, forget the decisions of epochs before ``t_s - window_s``."""
        if self.window_s <= 0.0:
            return
        while self._events and self._events[0][0] < float(t_s) - self.window_s - 1e-9:
            _, approved, expired = self._events.popleft()
            self.approved.subtract(approved)
            self.requested.subtract(approved)
            self.requested.subtract(expired)

    def factor(self, operator: str) -> int:
        """phi_o = round(F (n_o + 1) / (a_o + 1)), clipped to [F, F * FAIR_MAX_RATIO]."""
        n, a = self.requested[operator], self.approved[operator]
        # exact rational rounding (half up), so no float rounding decides a weight
        phi = (2 * FAIR_RESOLUTION * (n + 1) + (a + 1)) // (2 * (a + 1))
        return int(min(max(phi, FAIR_RESOLUTION), FAIR_RESOLUTION * FAIR_MAX_RATIO))


@dataclass
class EpochWeights:
    """The weights of one epoch and how they were bounded.

    Attributes:
        weights: (v,) float64 candidate weights (whole numbers except for ``paper``).
        step_s: seconds per step of the secondary term (``count``, ``priority``, ``fair``; 0 when
            the secondary term had to be dropped; 1 unless the bound needed coarser steps).
        exact_for_integer_backends: False when the weights exceed ``w_max`` (integer backends
            then round them).
    """

    weights: np.ndarray
    step_s: int = 1
    exact_for_integer_backends: bool = True


def added_cost_s(req_of: np.ndarray, departure_s: np.ndarray, duration_s: np.ndarray) -> np.ndarray:
    """c_v [s]: the delay and detour a candidate adds to its request's best candidate of this
    epoch, (departure - earliest departure among the request's candidates) + (flight time -
    least flight time among them); >= 0. O(v)."""
    req_of = np.asarray(req_of, dtype=np.int64)
    dep = np.asarray(departure_s, dtype=np.float64)
    dur = np.asarray(duration_s, dtype=np.float64)
    if req_of.size == 0:
        return np.zeros(0)
    m = int(req_of.max()) + 1
    lo = np.full(m, np.inf)
    best = np.full(m, np.inf)
    np.minimum.at(lo, req_of, dep)
    np.minimum.at(best, req_of, dur)
    return np.maximum((dep - lo[req_of]) + (dur - best[req_of]), 0.0)


def _whole_seconds(x: np.ndarray) -> np.ndarray:
    # 1e-6 s absorbs float noise of sums of times, so 30.0000000001 s is 30 s
    return np.ceil(np.asarray(x, dtype=np.float64) - 1e-6).clip(min=0).astype(np.int64)


def lexicographic_weights(primary: np.ndarray, cost_s: np.ndarray, n_requests: int,
                          w_max: int = W_MAX) -> EpochWeights:
    """w = p B + q: the sum of the primary values p first (exactly), then the least total cost.

    Args:
        primary: (v,) whole numbers >= 1 per candidate (1 for ``count``, the class or operator
            value otherwise); the candidates of one request must share it.
        cost_s: (v,) the cost [s] of each candidate (>= 0), in steps of ``step_s`` seconds:
            c = ceil(cost / step_s), q = Q - c with Q = max c + 1 (so q >= 1).
        n_requests: m, the requests the candidates belong to (at most one selected per request,
            so any selection's sum of q is at most m Q < B = m Q + 1).
        w_max: the bound on every weight; ``step_s`` is the least whole number of seconds that
            keeps max p B + Q within it (q = 0, B = 1 when even one step per request does not).
    Returns: EpochWeights. O(v).
    """
    p = np.asarray(primary, dtype=np.int64)
    cost = np.asarray(cost_s, dtype=np.float64)
    if p.size == 0:
        return EpochWeights(np.zeros(0))
    m = max(int(n_requests), 1)
    pmax = int(p.max())
    c1 = _whole_seconds(cost)
    cmax = int(c1.max())
    # largest Q with pmax (m Q + 1) + Q <= w_max
    q_cap = (w_max - pmax) // (pmax * m + 1)
    if q_cap >= 1:
        step = 1 if cmax + 1 <= q_cap else -(-cmax // (q_cap - 1)) if q_cap > 1 else 0
        if step:
            c = -(-c1 // step)  # ceil in whole steps
            big_q = int(c.max()) + 1
            q = big_q - c
        else:  # one level: every q would be equal, so the secondary term says nothing
            big_q, q = 0, np.zeros_like(p)
    else:
        step, big_q, q = 0, 0, np.zeros_like(p)
    b = m * big_q + 1
    top = pmax * b + big_q
    if top >= FLOAT_EXACT:
        raise ObjectiveRangeError(
            f"weights: the primary values reach {pmax} over {m} requests; the exact weights "
            f"({top}) exceed 2^53 (too many priority classes with too many requests)")
    w = p * b + q
    return EpochWeights(w.astype(np.float64), step_s=int(step), exact_for_integer_backends=top <= w_max)


def priority_values(priorities: Sequence[int]) -> np.ndarray:
    """P per request: the classes present ranked from the lowest, P = 1 for the lowest and
    P_r = 1 + sum of P over every request of a lower class, so one request of a class outweighs
    all requests of lower classes together. Exact Python integers (object array). O(m log m)."""
    pr = [int(x) for x in priorities]
    counts = Counter(pr)
    value, below = {}, 0
    for cls in sorted(counts):
        value[cls] = below + 1
        below += counts[cls] * value[cls]
    return np.array([value[x] for x in pr], dtype=object)


def delay_weights(req_of: np.ndarray, departure_s: np.ndarray, duration_s: np.ndarray,
                  requests: Sequence, t_s: float, epoch_s: float) -> EpochWeights:
    """``delay``: w = max(1, D_not - D_v) in whole seconds (the saving rounded down, with 1 us of
    tolerance for float noise), with D_v = departure - earliest + detour (detour: flight time - least flight time) the
    delay of candidate v counted from the request's earliest departure, and D_not the least delay
    if not approved now: (t + epoch_s - earliest) when the request may still depart at the next
    epoch, else (refused) latest - earliest + REFUSAL_EPOCHS epoch_s. O(v)."""
    req_of = np.asarray(req_of, dtype=np.int64)
    if req_of.size == 0:
        return EpochWeights(np.zeros(0))
    dep = np.asarray(departure_s, dtype=np.float64)
    dur = np.asarray(duration_s, dtype=np.float64)
    m = int(req_of.max()) + 1
    best = np.full(m, np.inf)
    np.minimum.at(best, req_of, dur)
    earliest = np.array([float(r.earliest_departure_s) for r in requests[:m]])
    latest = np.array([float(r.latest_departure_s) for r in requests[:m]])
    nxt = float(t_s) + float(epoch_s)
    urgent = latest < nxt
    d_not = np.where(urgent, latest - earliest + REFUSAL_EPOCHS * float(epoch_s), nxt - earliest)
    d_v = (dep - earliest[req_of]) + (dur - best[req_of])
    saving = np.floor(d_not[req_of] - d_v + 1e-6)
    return EpochWeights(np.maximum(saving, 1.0).astype(np.float64), step_s=1)


BASELINE_ORDERS = ("arrival", "priority")


def order_requests(requests: Sequence, order: str = "arrival") -> list:
    """The order in which the baselines (FIFO, first-fit) serve requests.

    ``arrival``: as given (arrival order, the paper's FIFO). ``priority``: the highest priority
    class first, then the earliest latest departure (earliest deadline first: a request whose
    window closes before the next epoch comes before any that can still wait), then arrival
    order. Stable; O(m log m).
    """
    if order not in BASELINE_ORDERS:
        raise ValueError(f"baseline_order must be one of {BASELINE_ORDERS}, got {order!r}")
    if order == "arrival":
        return list(requests)
    return sorted(requests, key=lambda r: (-int(getattr(r, "priority", 0)),
                                           float(r.latest_departure_s)))


def epoch_weights(objective: str, t_s: float, epoch_s: float, requests: Sequence,
                  req_of, departure_s, duration_s, paper_weights,
                  shares: OperatorShares | None = None, w_max: int | None = None) -> EpochWeights:
    """The weights of one epoch's candidates under ``objective``.

    Args:
        objective: a registered objective (:func:`objective_names`).
        t_s, epoch_s: the epoch's time and length [s].
        requests: the eligible requests (FlightRequest: earliest/latest departure, priority,
            operator); ``req_of[v]`` indexes them.
        req_of, departure_s, duration_s: per candidate: its request, departure [s] and flight
            time [s] (climb, cruise, descent).
        paper_weights: per candidate, the paper's weights (returned as they are for ``paper``).
        shares: the running OperatorShares (``fair``; empty counts when None).
        w_max: weight bound (default ``min(W_MAX, (2^31 - 1) // v)``: exact for every integer
            backend, KaMIS's 32-bit sums included).
    Returns: EpochWeights. Deterministic; O(v + m log m).
    """
    check_objective(objective)
    req_of = np.asarray(req_of, dtype=np.int64)
    n = int(req_of.size)
    if w_max is None:
        w_max = min(W_MAX, (2**31 - 1) // max(n, 1))
    return _REGISTRY[objective].weights(WeightContext(
        float(t_s), float(epoch_s), requests, req_of, departure_s, duration_s, paper_weights,
        shares if shares is not None else OperatorShares(), int(w_max)))


def _paper(ctx: WeightContext) -> EpochWeights:
    return EpochWeights(np.asarray(ctx.paper_weights, dtype=np.float64), step_s=0,
                        exact_for_integer_backends=False)


def _delay(ctx: WeightContext) -> EpochWeights:
    return delay_weights(ctx.req_of, ctx.departure_s, ctx.duration_s, ctx.requests, ctx.t_s, ctx.epoch_s)


def _lexicographic(ctx: WeightContext, primary: np.ndarray) -> EpochWeights:
    """Weights of a primary term per candidate, then the least added delay and detour."""
    cost = added_cost_s(ctx.req_of, ctx.departure_s, ctx.duration_s)
    return lexicographic_weights(primary, cost, len(ctx.requests), ctx.w_max)


def _count(ctx: WeightContext) -> EpochWeights:
    return _lexicographic(ctx, np.ones(int(ctx.req_of.size), dtype=np.int64))


def _priority(ctx: WeightContext) -> EpochWeights:
    requests = ctx.requests
    values = priority_values([getattr(r, "priority", 0) for r in requests])
    if max(values, default=1) >= FLOAT_EXACT:
        raise ObjectiveRangeError(
            f"priority: {len(set(getattr(r, 'priority', 0) for r in requests))} classes over "
            f"{len(requests)} requests need class values above 2^53")
    return _lexicographic(ctx, np.array([int(values[i]) for i in ctx.req_of.tolist()], dtype=np.int64))


def _fair(ctx: WeightContext) -> EpochWeights:
    phi = [ctx.shares.factor(operator_of(r)) for r in ctx.requests]
    return _lexicographic(ctx, np.array([phi[i] for i in ctx.req_of.tolist()], dtype=np.int64))


register_objective("paper", "the paper's weights (w = d*/d)", _paper)
register_objective("count", "approvals first, then least added delay and detour", _count)
register_objective("delay", "the delay from the earliest departure an approval saves", _delay)
register_objective("priority", "a flight of a higher priority class is never refused for any number of lower ones",
                   _priority)
register_objective("fair", "proportional fairness between operators from the running approval shares", _fair)
#: the built-in objectives (:func:`objective_names` also lists any registered later)
OBJECTIVES = objective_names()


def main(argv=None) -> int:
    """``python -m uam_planner.objectives``: the registered objectives, one per line."""
    for o in _REGISTRY.values():
        print(f"{o.name:10s} {o.summary}")
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main())
