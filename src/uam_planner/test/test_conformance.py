"""The planner's own observations of the vehicles (uam_planner.conformance.PositionBook)."""

import numpy as np


def test_a_fleet_state_observed_at_once_is_each_vehicle_observed():
    """``PositionBook.observe_many`` (the planner node's path: one call per fleet state) keeps
    what :meth:`observe` of each row keeps: out-of-order and repeated samples, bad rows refused
    one by one (named), the others recorded."""
    from uam_planner.conformance import PositionBook
    rows = [(10.0, ["a", "b"], [[1, 2, 3], [4, 5, 6]]),
            (5.0, ["a", "c"], [[0, 0, 0], [7, 8, 9]]),              # before a's newest
            (10.0, ["a"], [[99, 99, 99]]),                            # a repeat: the first kept
            (11.0, ["a", "", "b"], [[1, 1, 1], [2, 2, 2], [np.nan, 0, 0]])]
    one, many = PositionBook(), PositionBook()
    why = []
    for t, ids, pos in rows:
        for rid, p in zip(ids, pos):
            one.observe(rid, t, p)
        why.append(many.observe_many(ids, t, pos))
    for rid in ("a", "b", "c"):
        assert many.observations(rid, 0.0, 20.0) == one.observations(rid, 0.0, 20.0), rid
    assert why[:3] == [None, None, None]
    assert why[3].startswith("2 of 3 rows refused") and "request_id" in why[3]
    assert "t_s" in many.observe_many(["a"], float("nan"), [[0, 0, 0]])
    assert "positions_m" in many.observe_many(["a", "b"], 12.0, [[0, 0, 0]])


def test_overruns_with_the_sightings_cache_are_those_without():
    """``overruns(..., cache)``: the planned times of the sightings kept from one epoch to the
    next give the same held flights, epoch by epoch, as computing every sighting again; a
    flight flying at 70 % of its planned speed is held, one on time is not, and a new plan
    version starts its cache afresh."""
    from dataclasses import replace

    from uam_planner.conformance import PositionBook
    from uam_planner.nonconformance import overruns
    from uam_planner.planning_config import Flight
    from uam_planner.trajectory import Trajectory

    def flight(rid, t0, pts):
        times = t0 + np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1) / 10.0)))
        tr = Trajectory(times, pts)
        return Flight(rid, "A", "B", ("A", "B"), tr, float(times[0]), float(times[-1]),
                      float(times[-1] - times[0]) * 10.0, 1.0, 0, "mwis", "exact", 0)

    pts = np.array([[0, 0, 0], [0, 0, 60], [900, 0, 60], [900, 700, 60], [900, 700, 0]], float)
    late, on_time = flight("late", 0.0, pts), flight("on-time", 5.0, pts + [0, 300, 0])
    plans = {"late": late, "on-time": on_time}
    with_cache, without = {}, {}
    book, cache, held = PositionBook(), {}, set()
    for step in range(0, 300):
        t = float(step)
        book.observe("late", t, late.trajectory.position_at(min(0.7 * t, late.arrival_s)))
        if t >= on_time.departure_s:
            book.observe("on-time", t, on_time.trajectory.position_at(min(t, on_time.arrival_s)))
        if step % 30 == 29:
            book.prune(t)
            if step == 149:   # a new version of the late flight: its cache starts afresh
                plans["late"] = replace(late, version=2)
            with_cache = overruns(t, plans, book, with_cache, cache)
            without = overruns(t, plans, book, without)
            assert set(with_cache) == set(without), t
            held |= set(with_cache)
            if "late" in plans and "late" in cache:
                assert cache["late"][0] is plans["late"].trajectory
            for rid, o in with_cache.items():
                w = without[rid]
                assert (o.observed_s, o.latest.arrival_s, o.cap_s) == (w.observed_s, w.latest.arrival_s, w.cap_s)
                assert (o.newest is None) == (w.newest is None)
                if o.newest is not None:
                    assert o.newest.arrival_s == w.newest.arrival_s
    assert held == {"late"}
    assert set(cache) <= set(plans)
