"""The run's record (uam_sim.audit.record) over generated runs: whatever constraints an authority
adds, changes and withdraws mid-run, every flight's versions chain (no gap, no jump: the record
has no problem), its parts in force follow each other in time and space, a cancellation ends its
flight where it was planned to, and the runner's incursion count is the record's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uam_planner.constraints import Constraint
from uam_sim.runner.experiment_config import make_config
from uam_sim.runner.network_spec import load_network_spec
from uam_sim.runner.scenario import run_scenario

TINY = "config/networks/tiny.yaml"


def _run(seed: int):
    net = load_network_spec(TINY)
    rng = np.random.default_rng(seed)
    xy = np.asarray(net.enu_m)[:, :2]
    centre = tuple(float(v) for v in xy[rng.integers(len(xy))])
    radius = float(rng.uniform(100.0, 400.0))
    k_add, k_change, k_drop = sorted(rng.choice(np.arange(2, 12), size=3, replace=False).tolist())

    def before(planner, t, k):
        zone = Constraint("zone", 1, "generated", t, t + 2000.0, center_m=centre, radius_m=radius,
                          lower_m=0.0, upper_m=500.0)
        if k == k_add:
            assert planner.update_constraint("add", zone, t) is None
        elif k == k_change:
            bigger = Constraint("zone", 2, "generated", t, t + 2000.0, center_m=centre, radius_m=radius * 1.5,
                                lower_m=0.0, upper_m=500.0)
            assert planner.update_constraint("change", bigger, t) is None
        elif k == k_drop:
            assert planner.update_constraint("withdraw", "zone", t) is None
    return run_scenario(net, "greedy", 4.0, seed, 480.0, make_config({"network": TINY}), before_epoch=before)


@pytest.mark.parametrize("seed", range(6))
def test_the_record_of_a_generated_run_with_live_constraints_chains(seed):
    res = _run(seed)
    record = res.record
    assert record is not None and record.problems == [], record.problems
    assert len(record.applied) >= 1
    updated = [f for f in record.flights if f.updated]
    for f in record.flights:
        parts = f.flown.trajectories()
        for (t0, x0), (t1, x1) in zip(parts, parts[1:]):
            assert t1[0] == pytest.approx(t0[-1], abs=1e-9), f.key
            assert float(np.max(np.abs(x1[0] - x0[-1]))) <= 1e-3, f.key
        last = f.versions[-1]
        if not last.waypoints:   # a cancellation: nothing flown after it took effect
            assert not parts or parts[-1][0][-1] <= last.effective_s + 1e-9, f.key
        elif parts:
            assert parts[-1][0][-1] == pytest.approx(float(last.times_s[-1])), f.key
    found, _gap = record.incursions()
    assert res.summary.get("incursions") == len(found)
    # the runner's plans' audit is the record's parts, never a part with itself
    if updated:
        assert res.summary["losses"] == 0 and math.isfinite(res.summary["min_separation_m"] or math.inf)
