"""The stateful planner: ``Planner`` holds the pending requests and active flights between epochs; the ROS planner node and
the in-process experiment runner both drive it, so they approve the same flights for the same
inputs. Wall time is measured only for reports (``solve_time_s``, ``planning_time_s``); no
decision depends on it.

One epoch is :mod:`uam_planner.epoch` (framework steps 1-7 and the shortest-FIFO baseline);
the configuration is :mod:`uam_planner.planning_config`. Both are re-exported here, so
``from uam_planner.planning import PlanningConfig, Planner`` keeps working.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Callable, Sequence

import numpy as np

from .candidates import CandidateCache
from .conflict_graph import ActiveFlightIndex, CandidatePairCache
from .conformance import Claim, PositionBook, deviations, verify
from .constraints import ConstraintSet
from .epoch import (
    EpochReport,
    EpochResult,
    PreparedEpoch,
    _epoch_candidates,
    call_solver,
    checked_selection,
    commit_epoch,
    default_solve_mwis,
    departure_slots_s,
    plan_epoch_fifo,
    plan_epoch_mwis,
    prepare_epoch_mwis,
    replan_selector,
)
from .first_fit import as_firstfit, first_fit_select
from .nonconformance import overruns, predicted_conflicts, react_steps
from .objectives import OperatorShares, check_priority, operator_of
from .planning_config import (
    MAX_HORIZON_EPOCHS,
    POLICIES,
    REPLAN_POLICIES,
    AirspaceConfig,
    Flight,
    FlightRequest,
    PlanningConfig,
)

#: the planner's public names, with those of the configuration and the epoch it re-exports
__all__ = [
    "AirspaceConfig", "EpochReport", "EpochResult", "Flight", "FlightRequest",
    "MAX_HORIZON_EPOCHS", "POLICIES", "Planner", "PlanningConfig", "PreparedEpoch",
    "REPLAN_POLICIES", "_epoch_candidates", "call_solver", "checked_selection", "commit_epoch",
    "default_solve_mwis", "departure_slots_s", "plan_epoch_fifo", "plan_epoch_mwis",
    "prepare_epoch_mwis", "replan_selector"
]


# ---- the stateful planner -----------------------------------------------------------------------

class Planner:
    """Pending requests and active flights between epochs, with one policy.

    Args:
        network: the Network.
        config: PlanningConfig (default: paper defaults).
        policy: "mwis", "fifo" or "firstfit" (uam_planner.first_fit).
        solve_mwis: callable(weights, edges, groups) for the MWIS policy; default calls
            ``uam_solvers.solve`` with ``config.backend``.

    ``submit`` validates and queues a request; ``plan(t_s, epoch_index)`` runs one epoch, keeps
    the waiting requests, adds the approvals to the active flights and drops flights that landed
    before t_s. Each request is decided once: approved, expired or rejected.

    Examples:
        Two requests between the same aerodromes, one each way, planned in one epoch (the MWIS
        solved in process here; the default solves in worker processes with a deadline):

        >>> from uam_planner.synthetic import generate_network
        >>> from uam_solvers import solve
        >>> net = generate_network(60, 6, seed=1)
        >>> planner = Planner(net, solve_mwis=lambda w, e, g: solve(w, e, groups=g, backend="exact"))
        >>> planner.submit(FlightRequest("r1", "A000", "A001", 0.0, 0.0, 60.0)) is None
        True
        >>> planner.submit(FlightRequest("r2", "A001", "A000", 0.0, 0.0, 60.0)) is None
        True
        >>> result = planner.plan(0.0, 0)
        >>> sorted(f.request_id for f in result.approved), result.report.vertices
        (['r1', 'r2'], 10)
    """

    def __init__(self, network, config: PlanningConfig | None = None, policy: str = "mwis",
                 solve_mwis: Callable | None = None):
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
        self.network = network
        self._config = None
        self.config = config if config is not None else PlanningConfig()
        self.policy = policy
        # The default reads self.config at each call, so a new backend takes effect next epoch.
        self.solve_mwis = solve_mwis if solve_mwis is not None else self._default_solve
        self.pending: list[FlightRequest] = []
        self.active: list[Flight] = []
        # the active flights' segments, kept across epochs (rebuilt only if ``active`` is
        # replaced by a list that is not the previous one minus landed flights plus approvals)
        self.active_index = ActiveFlightIndex()
        self._known_ids: set[str] = set()
        self._rejected_since_plan = 0
        # wall time [s] of the route searches that ``submit`` ran since the last epoch (a new
        # origin-destination pair of a layered network is searched when it is validated): part
        # of the next epoch's planning time, its phase "routes_s"
        self._route_search_s = 0.0
        self._prepared: PreparedEpoch | None = None
        # requests decided (approved or expired) and approved per operator (the "fair"
        # objective's running shares, over the whole run or a sliding window)
        self.shares = OperatorShares(window_s=float(self.config.fair_window_s))
        # constraint updates (uam_planner.replanning): queued ones are applied at the
        # first epoch at a time >= their t_s; applied ones are logged in order
        self._queued_updates: list = []
        self._update_seq = 0
        self.constraint_log: list = []          # ConstraintUpdate, with applied_s
        self.initial_constraints: tuple = ()    # the constraints in force from the start
        self._requests: dict = {}               # request_id -> FlightRequest of active flights
        self._plan_updates: list = []           # decided in prepare, returned by commit
        self._cancellations: list = []          # cancel() since the last commit (PlanUpdate)
        # modifications (modify): request_id -> the replacement FlightRequest, decided at the
        # next epoch; while that epoch is planned, request_id -> (replacement, the version it
        # replaces or None, why None)
        self._modifying: dict = {}
        self._deciding: dict = {}
        self._replan_report = None
        # the reaction to nonconformance (uam_planner.nonconformance): the planner's
        # own observations of the vehicles and the reports (claims) not acted on yet
        self.positions = PositionBook()
        self._claims: list = []
        self._nonconformance_report = None
        # flights held past their plans (the safety gap; uam_planner.nonconformance
        # .overruns): request id -> Overrun, deconflicted against until its projection lands
        self.overruns: dict = {}
        self._sightings: dict = {}   # overruns' cache: the sightings' planned times per plan
        self.reaction_log: list = []   # the reports of the reactions between epochs

    @property
    def config(self) -> PlanningConfig:
        """The PlanningConfig; assigning a new one rebuilds the route cache only if k,
        penalty_factor, speed_mps or the vertical rates changed."""
        return self._config

    @config.setter
    def config(self, cfg: PlanningConfig) -> None:
        if not isinstance(cfg, PlanningConfig):
            raise TypeError(f"config must be a PlanningConfig, got {type(cfg).__name__}")
        old = self._config
        self._config = cfg
        # the horizon's conflicts between epochs (keyed by the route cache's templates, in this
        # config's separation): begun afresh with every config
        self.pair_cache = CandidatePairCache()
        route_fields = ("k", "penalty_factor", "speed_mps")
        vertical = ("climb_rate_mps", "descent_rate_mps")
        if old is None or any(getattr(old, f) != getattr(cfg, f) for f in route_fields) or \
                any(getattr(old.airspace, f) != getattr(cfg.airspace, f) for f in vertical):
            self.cache = CandidateCache(self.network, cfg.k, cfg.penalty_factor, cfg.speed_mps,
                                        cfg.airspace.climb_rate_mps,
                                        cfg.airspace.descent_rate_mps)
            if cfg.precompute_routes:
                self.cache.precompute()

    def set_constraints(self, constraints) -> None:
        """Plan from the next epoch on against ``constraints`` (a ConstraintSet, an iterable of
        Constraint checked against this planner's network, or None for none).

        A constraint with a finite ``announce_s`` is held back and added (an 'add' update, see
        :meth:`update_constraint`) at the first epoch at a time >= announce_s, when the flights
        it affects are re-planned; the others apply from the next epoch, and flights already
        approved are not revisited by this call. Replaces every constraint and every queued
        update given before."""
        from dataclasses import replace

        from .replanning import ConstraintUpdate
        if constraints is not None and not isinstance(constraints, ConstraintSet):
            constraints = ConstraintSet(constraints, self.network)
        now = [c for c in (constraints or ()) if not math.isfinite(c.announce_s)]
        later = sorted((c for c in (constraints or ()) if math.isfinite(c.announce_s)),
                       key=lambda c: c.announce_s)
        self._queued_updates = []
        for c in later:
            self._update_seq += 1
            self._queued_updates.append(ConstraintUpdate("add", c, float(c.announce_s), self._update_seq))
        if constraints is not None and later:
            constraints = ConstraintSet(now, self.network)
        self.initial_constraints = tuple(now)
        self.config = replace(self.config, constraints=constraints)

    def _projected_constraints(self) -> dict:
        """constraint id -> Constraint once every queued update is applied."""
        cur = {c.constraint_id: c for c in (self.config.constraints or ())}
        for u in sorted(self._queued_updates, key=lambda u: (u.t_s, u.seq)):
            if u.action == "withdraw":
                cur.pop(u.constraint.constraint_id, None)
            else:
                cur[u.constraint.constraint_id] = u.constraint
        return cur

    def update_constraint(self, action: str, constraint, t_s: float) -> str | None:
        """Queue a live constraint update; return None if accepted, else the reason (naming the
        field and value; nothing changes then).

        Args:
            action: 'add' (a new id), 'change' (a known id with a higher version) or
                'withdraw' (a known id; ``constraint`` may be the Constraint or its id).
            constraint: a ``uam_planner.constraints.Constraint`` (or an id for 'withdraw').
            t_s: when it is announced [s]; it is applied at the first epoch at a time >= t_s
                (or the next epoch, if that time has passed), before that epoch's requests are
                planned: the flights it affects are re-planned then (:mod:`uam_planner.replanning`)
                and the results are that epoch's ``EpochResult.plan_updates``. A constraint
                whose window has ended by t_s is refused.
        """
        from .replanning import ConstraintUpdate, check_update
        current = self._projected_constraints()
        reason = check_update(action, constraint, t_s, current, self.network)
        if reason is not None:
            return reason
        c = current[constraint if isinstance(constraint, str) else constraint.constraint_id] \
            if action == "withdraw" else constraint
        self._update_seq += 1
        self._queued_updates.append(ConstraintUpdate(action, c, float(t_s), self._update_seq))
        return None

    @property
    def queued_updates(self) -> list:
        """The constraint updates not applied yet, in the order they will be applied."""
        return sorted(self._queued_updates, key=lambda u: (u.t_s, u.seq))

    def replan_policy(self) -> str:
        """The re-plan policy in use: ``config.replan_policy``, or by default "mwis" for the MWIS
        policy and "firstfit" for the baselines."""
        return self.config.replan_policy or ("mwis" if self.policy == "mwis" else "firstfit")

    def _apply_constraint_updates(self, t_s: float, epoch_index: int):
        """The one place constraint updates take effect: at the epoch at ``t_s``,
        after landed flights are dropped and before the epoch's requests are planned. Applies
        every queued update due by ``t_s`` and, if one added or changed a constraint,
        re-plans the affected flights (``uam_planner.replanning.replan_steps``) and replaces
        them in ``active`` by their new versions (cancelled ones removed). A generator: it
        yields the re-plan's MWIS graphs (see :meth:`prepare_steps`)."""
        from dataclasses import replace

        from .replanning import apply_updates, replan_steps
        self._plan_updates, self._replan_report = [], None
        due = [u for u in self._queued_updates if u.t_s <= t_s]
        if not due:
            return
        due.sort(key=lambda u: (u.t_s, u.seq))
        self._queued_updates = [u for u in self._queued_updates if u.t_s > t_s]
        cset = apply_updates(self.config.constraints, due, self.network)
        applied = [replace(u, applied_s=float(t_s)) for u in due]
        self.constraint_log.extend(applied)
        self.config = replace(self.config, constraints=cset)
        labels = [f"{u.action} {u.constraint.label()}" for u in applied]
        if not any(u.action != "withdraw" for u in applied):
            from .replanning import ReplanReport
            self._replan_report = ReplanReport(t_s=float(t_s), policy=self.replan_policy(), updates=labels)
            return
        cfg = self.config
        active, updates, report = yield from replan_steps(
            t_s, epoch_index, self.active, self._requests, self.network, cfg, self.cache, cset,
            replan_selector(self.solve_mwis, cfg, epoch_index, t_s),
            lambda t, r: departure_slots_s(t, r, cfg), self.replan_policy(), labels=labels,
            # the flights held past their plans are in the air: every re-planned
            # version avoids their projections as it avoids the other active flights
            held=[(k, h.trajectory) for k, o in self.overruns.items() for h in o.flights])
        self.active = active
        self._plan_updates, self._replan_report = updates, report

    def observe(self, request_id: str, t_s: float, position_m) -> str | None:
        """The planner's own observation of a vehicle (its position in the fleet state at
        ``t_s``); what a nonconformance report is checked against. Returns None, or why the
        observation was refused (naming the field and value)."""
        return self.positions.observe(request_id, t_s, position_m)

    def observe_fleet(self, request_ids, t_s: float, positions_m) -> str | None:
        """The planner's own observations of every vehicle of a fleet state at ``t_s``
        (``positions_m`` (n, 3), row i of ``request_ids[i]``), as :meth:`observe` of each."""
        return self.positions.observe_many(request_ids, t_s, positions_m)

    def report_nonconforming(self, request_id: str, t_s: float, source: str = "") -> str | None:
        """A claim that ``request_id`` is nonconforming at ``t_s`` (from the conformance
        monitor). None if queued, else why it is refused (naming the field and value). Queued
        claims are checked at the first epoch at a time >= t_s against the planner's own plan and
        observation (:func:`uam_planner.nonconformance.verify`) and acted on only if they hold:
        a report can at worst cause one deconflicted update of a flight the planner itself sees
        outside its plan, never the removal of a flight."""
        if self.config.conformance is None:
            return "conformance: the reaction to nonconformance is off (PlanningConfig.conformance is None)"
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) \
                or not math.isfinite(t_s):
            return f"t_s: {t_s!r} is not a finite time"
        if not isinstance(request_id, str) or not (
                any(f.request_id == request_id for f in self.active) or request_id in self.overruns):
            return f"request_id: {request_id!r} is neither an active flight of this planner nor held past its plan"
        if any(c.request_id == request_id for c in self._claims):
            return None  # already queued: one update per flight and epoch
        self._claims.append(Claim(request_id, float(t_s), str(source)))
        return None

    def _react_to_nonconformance(self, t_s: float, epoch_index: int):
        """Step 2b of ``prepare`` (after the constraint re-plan, before new requests): the claims
        due by ``t_s`` that the planner's own view confirms get their intents updated from where
        the flights are (``uam_planner.nonconformance.react_steps``), deconflicted in one batch.
        A claim may be about a flight held past its plan (``self.overruns``: late, still in the
        air after its planned arrival): its newest version joins the batch like an active flight
        and, updated, is active again. A generator: it yields the batch's MWIS graph (see
        :meth:`prepare_steps`)."""
        self._nonconformance_report = None
        due = [c for c in self._claims if c.t_s <= t_s]
        probe_s = float(self.config.conflict_probe_s)
        if (not due and not probe_s) or self.config.conformance is None:
            return
        self._claims = [c for c in self._claims if c.t_s > t_s]
        where = {f.request_id: i for i, f in enumerate(self.active)}
        found, refused, readmitted = {}, [], set()
        for c in due:
            i = where.get(c.request_id)
            held = self.overruns.get(c.request_id) if i is None else None
            if i is None and held is None:
                refused.append((c.request_id, f"request_id: {c.request_id!r} is neither active "
                                              f"nor held past its plan"))
                continue
            flight = self.active[i] if held is None else held.plan
            obs = self.positions.latest(c.request_id, until=t_s)
            got, why = verify(flight, obs, self.config.conformance, t_s)
            if got is None:
                refused.append((c.request_id, why))
                continue
            if held is not None:
                # held past its plan (dropped from the active flights at this epoch, still in
                # the air): its plan is updated like an active one's, from where it is
                self.active.append(flight)
                i = len(self.active) - 1
                readmitted.add(id(flight))
            found[i] = (obs, got)
        updates, rep_ = yield from self._update_batch(t_s, epoch_index, found)
        if readmitted:   # one left without an update (nothing of its plan left) stays held only
            self.active = [f for f in self.active if id(f) not in readmitted]
        rep_["refused"] = refused
        self._nonconformance_report = rep_
        if probe_s:
            yield from self._probe(t_s, epoch_index, {u.request_id for u in updates})

    def _update_batch(self, t_s: float, epoch_index: int, found: dict, probed: dict | None = None,
                      held: Sequence = ()):
        """One batch of the reaction (``nonconformance.react_steps``) on the active flights,
        deconflicted against every other one and the held flights' projections; the new
        versions replace the old in ``self.active`` and join this epoch's plan updates.
        A generator (it yields the batch's MWIS graph); returns (updates, report)."""
        from .replanning import _Router
        cfg = self.config
        mine = {self.active[i].request_id for i in found}
        router = _Router(self.network, self.cache, cfg.constraints if cfg.constraints is not None
                         else (), t_s)
        active, updates, rep_ = yield from react_steps(
            t_s, epoch_index, self.active, found, self.positions, cfg,
            replan_selector(self.solve_mwis, cfg, epoch_index, t_s), self.replan_policy(), self.network,
            fixed=[h.trajectory for k, o in self.overruns.items() if k not in mine for h in o.flights],
            fixed_ids=[k for k, o in self.overruns.items() if k not in mine for _h in o.flights],
            probed=probed, held=held, router=router)
        for u in updates:   # the new version is drawn from where it is: its overrun is redrawn
            self.overruns.pop(u.request_id, None)
        self.active = active
        self._plan_updates = list(self._plan_updates) + list(updates)
        return updates, rep_

    def _probe(self, t_s: float, epoch_index: int, updated: set):
        """The conflict probe (``PlanningConfig.conflict_probe_s``, docs/disturbances.md), after
        the reaction to reported nonconformance: the airborne flights not updated just now whose
        rest of plan, flown from the planner's own newest sighting at their observed progress
        rate, loses the true minimum with another's within the look-ahead are updated from where
        they are, in one batch (each may also keep its plan: it conforms). A generator: it
        yields the batch's MWIS graph."""
        cfg = self.config
        skip = [i for i, f in enumerate(self.active) if f.request_id in updated]
        got = predicted_conflicts(self.active, self.positions, t_s, float(cfg.conflict_probe_s),
                                  cfg.probe_separation, exclude=skip)
        if not got:
            return
        found = {}
        for i, (obs, _ids) in got.items():   # the sighting the projection started from
            errs = deviations(self.active[i].trajectory, [obs.t_s], [obs.position_m])
            found[i] = (obs, tuple(float(x[0]) for x in errs))
        # the flights they are predicted to meet: those due to depart may be held on the pad
        # (``_probe_batch_steps`` keeps only those)
        where = {f.request_id: i for i, f in enumerate(self.active)}
        held = sorted({where[r] for _obs, ids in got.values() for r in ids if r in where})
        _updates, rep_ = yield from self._update_batch(
            t_s, epoch_index, found, probed={i: ids for i, (_obs, ids) in got.items()}, held=held)
        rep = self._nonconformance_report or {}
        rep["probe"] = {k: v for k, v in rep_.items() if k != "rates"}
        self._nonconformance_report = rep

    def react_between(self, t_s: float, epoch_index: int) -> list:
        """:meth:`react_between_steps` with the reaction's MWIS graph solved here (``solve_mwis``)."""
        from .replanning import SOLVE_HERE, run_steps
        return run_steps(self.react_between_steps(t_s, epoch_index), lambda _graph: SOLVE_HERE)

    def react_between_steps(self, t_s: float, epoch_index: int):
        """The reaction between epochs (F3548 asks a nonconforming intent to be
        updated within 5 s, an epoch is 30 s): the claims due by ``t_s`` are checked and acted on
        now, exactly as at step 2b of :meth:`prepare` (the planner's own observations stamped up
        to ``t_s``, its newest plans; every update deconflicted against every other active flight
        and every held flight's projections from ``t_s`` on). Returns the PlanUpdates (also in
        ``self.reaction_log``); the active flights take the new versions at once. Nothing else
        changes: no request is planned, no flight dropped. Not while an epoch is prepared.
        A generator, as :meth:`prepare_steps`: it yields the reaction's MWIS graph and takes back
        the solver's answer (the planner node awaits the solver service for it); its return
        value is the list of PlanUpdates."""
        if self._prepared is not None:
            raise RuntimeError(f"epoch {self._prepared.epoch_index} is prepared but not committed")
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if self.config.conformance is None or (not self._claims and not self.config.conflict_probe_s):
            return []
        self._hold_overruns(t_s)
        saved, saved_rep = self._plan_updates, self._nonconformance_report
        self._plan_updates = []
        try:
            yield from self._react_to_nonconformance(t_s, epoch_index)
            updates, rep = list(self._plan_updates), self._nonconformance_report
        finally:
            self._plan_updates, self._nonconformance_report = saved, saved_rep
        if rep is not None and (updates or rep.get("refused")):
            self.reaction_log.append(rep)
        return updates

    def _default_solve(self, weights, edges, groups):
        return default_solve_mwis(self._config)(weights, edges, groups)

    def record_rejection(self) -> None:
        """Count a request rejected before ``submit`` (e.g. a malformed message) in the next
        epoch's report."""
        self._rejected_since_plan += 1

    def validate(self, request: FlightRequest, replacing: bool = False) -> str | None:
        """Why ``request`` cannot be accepted (naming the field and value), or None. ``replacing``:
        it is a new version of a request already known (:meth:`modify`), not a new request."""
        rid = getattr(request, "request_id", None)
        if not isinstance(rid, str) or not rid:
            return f"request_id: {rid!r} is not a non-empty string"
        if rid in self._known_ids and not replacing:
            return f"request_id: {rid!r} duplicates an earlier request"
        net = self.network
        for name in ("origin_id", "destination_id"):
            node = getattr(request, name)
            i = net.index.get(node) if isinstance(node, str) else None
            if i is None:
                return f"{name}: {node!r} is not a node of network {net.name!r}"
            if not net.is_aerodrome[i]:
                return f"{name}: {node!r} is not an aerodrome of network {net.name!r}"
        if request.origin_id == request.destination_id:
            return (f"destination_id: {request.destination_id!r} is the same as origin_id "
                    f"{request.origin_id!r}")
        for name in ("request_time_s", "earliest_departure_s", "latest_departure_s"):
            v = getattr(request, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v):
                return f"{name}: {v!r} is not a finite time"
        problem = check_priority(getattr(request, "priority", 0))
        if problem:
            return problem
        op = getattr(request, "operator_id", "")
        if not isinstance(op, str):
            return f"operator_id: {op!r} is not a string"
        grants = self.config.priority_grants
        if grants is not None:   # a class above the operator's grant (uam_planner.grants)
            problem = grants.check(op or rid.split("/", 1)[0], getattr(request, "priority", 0))
            if problem:
                return problem
        if request.latest_departure_s < request.earliest_departure_s:
            return (f"latest_departure_s: {request.latest_departure_s!r} is before "
                    f"earliest_departure_s {request.earliest_departure_s!r}")
        if net.layered:
            # vertiports are terminals: a pair may have no route that avoids the others (the
            # Network only guarantees reachability through them); the routes are cached anyway
            misses = self.cache.misses
            t = time.perf_counter()
            try:
                self.cache.templates(net.index[request.origin_id], net.index[request.destination_id])
            except ValueError as exc:
                return f"destination_id: {exc}"
            finally:
                if self.cache.misses != misses:
                    self._route_search_s += time.perf_counter() - t
        return None

    def submit(self, request: FlightRequest) -> str | None:
        """Queue ``request``; return None if accepted, else the rejection reason."""
        reason = self.validate(request)
        if reason is not None:
            self._rejected_since_plan += 1
            return reason
        self._known_ids.add(request.request_id)
        self.pending.append(request)
        return None

    def _between_epochs(self, request_id, t_s) -> str | None:
        if self._prepared is not None:
            return (f"request_id: {request_id!r}: epoch {self._prepared.epoch_index} is prepared; "
                    "ask again after its commit")
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) \
                or not math.isfinite(t_s):
            return f"t_s: {t_s!r} is not a finite time"
        return None

    def cancel(self, request_id: str, t_s: float, reason: str = "cancelled by its operator") -> str | None:
        """End ``request_id`` at ``t_s`` [s], as its operator asks: a waiting request is withdrawn
        (it is never decided), and so is a modification not decided yet (:meth:`modify`); an
        approved flight that has not departed by ``t_s`` is dropped, and the next :meth:`commit`
        reports it as a PlanUpdate of kind 'cancelled' (version + 1, effective ``t_s``), as a
        re-plan's cancellation is reported. An airborne flight is not cancelled (the aircraft
        flies; it lands as planned).

        Returns None when done, else why not (naming the field and value). Between epochs only:
        a prepared epoch holds its requests until it is committed."""
        from .replanning import PlanUpdate
        problem = self._between_epochs(request_id, t_s)
        if problem is not None:
            return problem
        for i, r in enumerate(self.pending):
            if r.request_id == request_id:
                del self.pending[i]
                return None
        f = self.flight(request_id)   # between epochs: the active one
        if f is None:
            return f"request_id: {request_id!r} is neither waiting nor an approved flight of this planner"
        if f.departure_s < t_s:
            return (f"request_id: {request_id!r} departed at {f.departure_s:g} s, before t_s {t_s:g} s: "
                    f"an airborne flight is not cancelled (it lands at {f.arrival_s:g} s)")
        self._modifying.pop(request_id, None)
        self.active = [a for a in self.active if a is not f]
        self._requests.pop(request_id, None)
        self._cancellations.append(PlanUpdate(request_id, f.operator_id, int(f.version) + 1, "cancelled", (),
                                              str(reason), float(t_s), None, f))
        return None

    def modify(self, request: FlightRequest, t_s: float) -> str | None:
        """Plan a new version of the approved flight ``request.request_id`` from ``request`` (its
        operator changed its plan: ends, window, priority), as of ``t_s`` [s]. Returns None if
        queued, else why not (naming the field and value): the flight must be approved, not
        departed by ``t_s``, and not already being modified; ``request`` is checked as
        :meth:`submit` checks a new one.

        Decided at the next epoch, and at that epoch only: there the flight in force is left out
        of the traffic (after that epoch's re-plans) and ``request`` is planned with the epoch's
        other requests, deconflicted against everything else. Approved, the new flight replaces
        the old in the active flights as version + 1 of the same request (a PlanUpdate of kind
        :data:`~uam_planner.replanning.KIND_MODIFIED`, effective at the epoch; the same F3548
        operational intent, a new version). Not approved (no conflict-free candidate at that
        epoch), the old version stays in force if it still keeps separation with every flight
        approved meanwhile and stays out of every constraint, else it is cancelled; either way
        :attr:`EpochResult.refused_modifications` says so. Deciding at one epoch keeps the old
        version out of the traffic for the planning of that one epoch only, never while it
        could depart or while a reaction between epochs deconflicts against it."""
        rid = getattr(request, "request_id", None)
        problem = self._between_epochs(rid, t_s)
        if problem is not None:
            return problem
        f = self.flight(rid)
        if f is None:
            return f"request_id: {rid!r} is not an approved flight of this planner"
        if f.departure_s < t_s:
            return (f"request_id: {rid!r} departed at {f.departure_s:g} s, before t_s {t_s:g} s: "
                    "an airborne flight is not re-planned by its operator")
        if rid in self._modifying:
            return f"request_id: {rid!r} has a modification waiting for the next epoch"
        reason = self.validate(request, replacing=True)
        if reason is not None:
            return reason
        self._modifying[rid] = request
        return None

    def _start_modifications(self, t_s: float) -> None:
        """At an epoch's prepare, after its re-plans: each modification's flight in force leaves
        the traffic and its replacement joins the epoch's requests (``_deciding``)."""
        self._deciding, mods, self._modifying = {}, self._modifying, {}
        for rid, req in mods.items():
            f = next((f for f in self.active if f.request_id == rid), None)
            if f is None:   # landed or cancelled by this epoch's re-plan
                self._deciding[rid] = (req, None, "the flight is no longer an approved flight of this planner")
                continue
            if f.departure_s < t_s:   # departed meanwhile: flies its plan
                self._deciding[rid] = (req, None, f"the flight departed at {f.departure_s:g} s; it flies its plan")
                continue
            self.active = [a for a in self.active if a is not f]
            self._deciding[rid] = (req, f, "")
            self.pending.append(req)

    def _keeps_out(self, f: Flight) -> str | None:
        """Why flight ``f`` may not rejoin the active flights (it loses separation with one, or
        enters a constraint), or None."""
        from .separation import any_conflict
        if self.active and bool(any_conflict([f.trajectory], [a.trajectory for a in self.active],
                                             self.config.separation)[0]):
            return "it now loses separation with a flight approved while it was out of the traffic"
        cset, net = self.config.constraints, self.network
        if cset is not None and len(cset):
            which, _ = cset.violations([f.trajectory], [net.index[f.origin_id]], [net.index[f.destination_id]])
            if which[0] >= 0:
                return f"it now enters constraint {cset.constraints[which[0]].constraint_id!r}"
        return None

    def _finish_modifications(self, result: EpochResult, t_s: float) -> list:
        """At the commit of the epoch that decided the modifications: approved replacements become
        new versions (PlanUpdates, out of ``result.approved``); the others are refused (out of
        ``result.expired`` and the waiting requests), their old versions put back or cancelled.
        Returns the PlanUpdates; ``result.refused_modifications`` gets the refusals."""
        from .replanning import KIND_MODIFIED, PlanUpdate
        deciding, self._deciding = self._deciding, {}
        if not deciding:
            return []
        updates = []
        new_versions = []
        for f in result.approved:
            got = deciding.get(f.request_id)
            if got is None or got[1] is None:
                continue
            old = got[1]
            new = replace(f, version=int(old.version) + 1, effective_s=float(t_s))
            new_versions.append(new)
            updates.append(PlanUpdate(f.request_id, old.operator_id, new.version, KIND_MODIFIED, (),
                                      f"modified by its operator: {new.origin_id} -> {new.destination_id}, "
                                      f"departs at {new.departure_s:g} s", float(t_s), new, old,
                                      float(new.arrival_s - old.arrival_s)))
        done = {f.request_id for f in new_versions}
        result.approved = [f for f in result.approved if f.request_id not in deciding]
        refusals = result.report.constraint_refusals if hasattr(result.report, "constraint_refusals") else {}
        result.expired = [r for r in result.expired if r.request_id not in deciding]
        result.waiting = [r for r in result.waiting if r.request_id not in deciding]
        result.report.approved, result.report.expired = len(result.approved), len(result.expired)
        self.active = self.active + new_versions
        for rid in sorted(set(deciding) - done):
            _req, old, gone = deciding[rid]
            if old is None:
                held = self.flight(rid) is not None
                result.refused_modifications[rid] = (f"request_id: {rid!r}: at the epoch at {t_s:g} s {gone}"
                                                     + ("; the previous version stays in force" if held else ""), held)
                continue
            why = refusals.get(rid) or f"no conflict-free candidate for the new version at the epoch at {t_s:g} s"
            lost = self._keeps_out(old)
            if lost is None:
                self.active = self.active + [old]
                result.refused_modifications[rid] = (f"{why}; the previous version stays in force", True)
            else:
                self._requests.pop(rid, None)
                updates.append(PlanUpdate(rid, old.operator_id, int(old.version) + 1, "cancelled", (),
                                          f"cancelled: {lost}", float(t_s), None, old))
                result.refused_modifications[rid] = (f"{why}; the previous version could not be kept: {lost}",
                                                     False)
        return updates

    def prepare(self, t_s: float, epoch_index: int) -> PreparedEpoch:
        """Prepare the epoch at ``t_s`` [s] up to its conflict graph; finish with :meth:`commit`.

        Requests submitted between prepare and commit wait for the next epoch. One prepared
        epoch at a time. The re-plan's graphs (step 2) are solved with ``solve_mwis`` here;
        :meth:`prepare_steps` hands them to the caller instead.
        """
        from .replanning import SOLVE_HERE, run_steps
        return run_steps(self.prepare_steps(t_s, epoch_index), lambda _graph: SOLVE_HERE)

    def prepare_steps(self, t_s: float, epoch_index: int):
        """:meth:`prepare` as a generator: it yields each MWIS graph of step 2's batch re-plan
        (``uam_planner.replanning.replan_steps``) and of step 2b's reaction to nonconforming
        flights (``uam_planner.nonconformance.react_steps``), and takes back the solver's answer for it
        (``send``: the answer, a reason string, or ``replanning.SOLVE_HERE``); its return value
        is the PreparedEpoch. The planner node awaits the solver service between the steps, as
        it does for the epoch's own graph; the decisions are those of :meth:`prepare` given the
        same answers."""
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if self._prepared is not None:
            raise RuntimeError(f"epoch {self._prepared.epoch_index} is prepared but not committed")
        self._hold_overruns(t_s)
        self.active = [f for f in self.active if f.arrival_s >= t_s]
        self.shares.advance(t_s)
        if self._requests:
            alive = {f.request_id for f in self.active}
            self._requests = {k: r for k, r in self._requests.items() if k in alive}
        yield from self._apply_constraint_updates(t_s, epoch_index)
        yield from self._react_to_nonconformance(t_s, epoch_index)
        self._start_modifications(t_s)
        # the traffic new requests are deconflicted against: the active flights, the held
        # flights' projections and, with the conflict probe, the airborne flights' projections
        # (new objects every epoch, after the active ones: the segment index stays incremental)
        held = [replace(h) for o in self.overruns.values() for h in o.flights]
        seen = self._projected_traffic(t_s)
        traffic = self.active + held + seen if held or seen else self.active
        if self.policy == "mwis":
            prep = prepare_epoch_mwis(t_s, epoch_index, self.pending, traffic, self.network, self.config,
                                      self.cache, self.active_index, self.shares,
                                      pair_cache=self.pair_cache)
        else:
            args = (t_s, epoch_index, self.pending, traffic, self.network, self.config)
            res = plan_epoch_fifo(*args, None, self.cache, self.active_index, self.shares) \
                if self.policy == "fifo" else \
                as_firstfit(plan_epoch_mwis(*args, first_fit_select, self.cache, self.active_index,
                                            self.shares, self.config.baseline_order,
                                            horizon=1))  # uam_planner.first_fit; myopic
            prep = PreparedEpoch(t_s=float(t_s), epoch_index=int(epoch_index), pending=list(self.pending),
                                 report=res.report, result=res)
        self._count_route_searches(prep)
        if held or seen:
            # each held flight is counted once (its plan, if still active, or one projection),
            # each projected one as its plan
            planned = {f.request_id for f in self.active}
            twice = sum(len(o.flights) - (k not in planned) for k, o in self.overruns.items())
            twice += len(seen)
            prep.airborne_count -= twice
            if prep.result is not None:
                prep.result.report.active_flights -= twice
            if held:
                prep.report.overruns = {k: o.until_s for k, o in self.overruns.items()}
        self._prepared = prep
        return prep

    def _count_route_searches(self, prep: PreparedEpoch) -> None:
        """The route searches ``submit`` ran for this epoch's requests become part of its
        planning time (phase "routes_s"): the epoch's figures hold everything it cost."""
        routes_s, self._route_search_s = self._route_search_s, 0.0
        if prep.result is not None:
            rep = prep.result.report
            rep.phase_times_s["routes_s"] = routes_s
            rep.planning_time_s += routes_s
        else:
            prep.phases["routes_s"] = routes_s
            prep.prepare_s += routes_s

    def _projected_traffic(self, t_s: float) -> list:
        """With the conflict probe on (``conflict_probe_s``): every airborne flight's projection
        (from the planner's newest sighting at its observed progress rate, up to the look-ahead;
        ``nonconformance.projections``) as a Flight, traffic that new requests are deconflicted
        against beside its plan (without it, a flight approved to leave a vertiport at once
        kept the buffer only from the plan of a flight landing there 15 s later, which landed
        4 s early, seen early by the probe: 91 m flown at a 25 m buffer). Empty otherwise."""
        cfg = self.config
        if cfg.conformance is None or not cfg.conflict_probe_s:
            return []
        from .nonconformance import projections
        return [replace(self.active[i], trajectory=pred, departure_s=float(pred.departure_s),
                        arrival_s=float(pred.arrival_s))
                for i, _obs, pred in projections(self.active, self.positions, t_s,
                                                 float(cfg.conflict_probe_s))]

    def _hold_overruns(self, t_s: float) -> None:
        """Step 1 of ``prepare``, before flights past their planned arrival are dropped: from
        the planner's own observations, the flights that fly past their plans and how long they
        are held (:func:`uam_planner.nonconformance.overruns`; docs/disturbances.md, section 6). Then
        the held flights whose projection has landed by ``t_s`` are let go, and observations of
        flights the planner no longer holds are forgotten."""
        plans = {o.request_id: o.plan for o in self.overruns.values()}
        plans.update((f.request_id, f) for f in self.active)
        self.positions.prune(t_s)
        if self.overruns or self.positions:
            self.overruns = overruns(t_s, plans, self.positions, self.overruns, self._sightings)
        self.positions.forget(set(f.request_id for f in self.active if f.arrival_s >= t_s) |
                              set(self.overruns))

    def commit(self, prep: PreparedEpoch, answer=None, solve_s: float = 0.0) -> EpochResult:
        """Commit a prepared epoch with the solver's ``answer`` (checked here, greedy fallback)
        and update the planner's state: waiting requests stay, approvals become active."""
        if prep is not self._prepared:
            raise RuntimeError("commit: this epoch was not prepared by this planner (or is committed)")
        self._prepared = None
        result = commit_epoch(prep, answer, self.config, solve_s)
        if self._deciding:   # the replacements' requests, by id (their flights keep their ids)
            by_id = {r.request_id: r for r in prep.pending}
            self._requests.update((f.request_id, by_id[f.request_id]) for f in result.approved
                                  if f.request_id in self._deciding)
        modified = self._finish_modifications(result, prep.t_s)
        result.plan_updates = self._cancellations + list(self._plan_updates) + modified
        self._cancellations = []
        result.report.replan = self._replan_report
        result.report.nonconformance = self._nonconformance_report
        self._plan_updates, self._replan_report, self._nonconformance_report = [], None, None
        if result.approved:
            by_id = {r.request_id: r for r in prep.pending}
            self._requests.update((f.request_id, by_id[f.request_id]) for f in result.approved
                                  if f.request_id in by_id)
        arrived_since = self.pending[len(prep.pending):]
        self.pending = list(result.waiting) + arrived_since
        self.active = self.active + list(result.approved)
        self.shares.record(prep.t_s, [operator_of(f) for f in result.approved],
                           [operator_of(r) for r in result.expired])
        result.report.rejected = self._rejected_since_plan
        self._rejected_since_plan = 0
        return result

    def plan(self, t_s: float, epoch_index: int) -> EpochResult:
        """Run one planning epoch at ``t_s`` [s] (prepare, solve with ``solve_mwis``, commit)."""
        prep = self.prepare(t_s, epoch_index)
        t = time.perf_counter()
        answer = call_solver(self.solve_mwis, prep.graph) if prep.needs_solver else None
        return self.commit(prep, answer, time.perf_counter() - t)

    def restore(self, flights: Sequence[Flight], decided_ids: Sequence[str] = ()) -> None:
        """Resume after a restart: ``flights`` are flying (they become active, their ids taken) and
        ``decided_ids`` were decided before (their ids are taken, nothing is planned for them).
        Adds only: a flight already active stays as it is, whatever ``flights`` says."""
        held = {f.request_id for f in self.active}
        new = [f for f in flights if f.request_id not in held]
        self.active = self.active + new
        for f in new:  # counted when they departed (the fair window's time)
            self.shares.record(f.departure_s, [operator_of(f)], [])
        self._known_ids.update(f.request_id for f in flights)
        self._known_ids.update(decided_ids)
        self.pending = [r for r in self.pending if r.request_id not in self._known_ids]

    def flight(self, request_id: str):
        """The approved flight of ``request_id`` in force (its newest version), or None."""
        f = next((f for f in self.active if f.request_id == request_id), None)
        if f is None and request_id in self._deciding:   # out of the traffic while its epoch is planned
            f = self._deciding[request_id][1]
        return f

    def is_known(self, request_id: str) -> bool:
        """True once ``request_id`` was accepted (or restored): a later request with it is a duplicate."""
        return request_id in self._known_ids
