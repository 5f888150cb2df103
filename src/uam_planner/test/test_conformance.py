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
