"""audit_trajectories' grid pre-filter of the pairs (issue 22, third stop: the city recording's
plans audit) gives the brute force's minimum, pair and losses: flights that lose separation, and
flights that never come within twice the minimum (the pre-filter leaves every pair out and the
search falls back to the box-ordered walk)."""

from __future__ import annotations

import numpy as np
import pytest

from uam_planner.audit import audit_flights
from uam_planner.separation import SeparationModel
from uam_sim.audit.separation import audit_trajectories


def _flights(rng, n, box_m):
    out = []
    for _ in range(n):
        m = int(rng.integers(2, 8))
        t = float(rng.integers(0, 100)) + np.cumsum(rng.uniform(5, 30, m))
        xy = rng.uniform(-box_m, box_m, 2) + np.cumsum(rng.normal(0, 150, (m, 2)), axis=0)
        z = rng.choice([60.0, 90.0, 120.0]) + np.zeros(m)
        out.append((t, np.column_stack([xy, z])))
    return out


@pytest.mark.parametrize("model", [100.0, SeparationModel("cylinder", 100.0, 30.0)])
@pytest.mark.parametrize("box_m", [400.0, 20000.0])
def test_prefiltered_audit_equals_the_brute_force(model, box_m):
    rng = np.random.default_rng(int(box_m))
    flights = _flights(rng, 40, box_m)
    labels = [f"f{i}" for i in range(len(flights))]
    got = audit_trajectories(flights, labels, model)
    ref = audit_flights(flights, model, labels=labels)
    assert got.min_separation_m == pytest.approx(ref.min_separation_m, rel=1e-12)
    assert sorted(tuple(sorted((a, b))) for a, b, _d, _t in got.losses) == sorted(tuple(sorted((a, b))) for a, b, _d, _t in ref.losses)
    if box_m == 400.0:
        assert got.losses   # not vacuous: a dense box loses separation
    else:
        assert got.min_separation_m > 200.0   # sparse: nothing within reach, the fallback walk


def test_two_far_flights_give_their_exact_distance():
    # parallel east-bound at the same level, 5 km apart: beyond any pre-filter reach
    a = (np.array([0.0, 100.0]), np.array([(0.0, 0.0, 90.0), (1000.0, 0.0, 90.0)]))
    b = (np.array([0.0, 100.0]), np.array([(0.0, 5000.0, 90.0), (1000.0, 5000.0, 90.0)]))
    got = audit_trajectories([a, b], ["a", "b"], 100.0)
    assert got.min_separation_m == pytest.approx(5000.0) and not got.losses
