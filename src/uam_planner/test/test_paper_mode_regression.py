"""Paper mode is unchanged: the approvals of the paper scenario for a fixed seed are pinned.

The scenario is the paper's (Singapore network, 10 requests per 30 s between random distinct
aerodromes, window 60 s, epoch 30 s, 5 candidates, separation 100 m), 3,500 s. Demand is drawn
here with numpy (the planner library must not import uam_sim). The digests (of every approval's request,
epoch, candidate, departure time and route) were computed on commit c0b12bd, before the airspace work (vertiports, levels, cylinder separation, departure slots)
started; the default PlanningConfig must keep giving exactly these decisions.
"""

import hashlib
from pathlib import Path

import numpy as np
import pytest

from uam_planner.network import load_network
from uam_planner.planning import FlightRequest, Planner, PlanningConfig

NETWORK = Path(__file__).resolve().parents[3] / "config" / "networks" / "singapore.yaml"


#: each (policy, backend, seed, rate)'s planner, demand and decisions after its latest test: the
#: 3,500 s test continues the 900 s one's run (the planner is causal, so its first 30 epochs are
#: the 900 s run), and the first 900 s are planned once when both tests run
_RUNS: dict = {}


def _run(policy: str, backend: str, seed: int = 7, rate: int = 10, duration_s: float = 3500.0):
    epochs = int(np.ceil(duration_s / 30.0))
    # taken out while it runs: a run that fails part way is not continued by the next test
    run = _RUNS.pop((policy, backend, seed, rate), None)
    if run is None or run["epochs"] > epochs:
        net = load_network(NETWORK)
        run = {"net": net, "epochs": 0, "n": 0, "decisions": [], "rng": np.random.default_rng(seed),
               "planner": Planner(net, PlanningConfig(backend=backend, seed=seed,
                                                      precompute_routes=False), policy)}
    net, planner, rng, decisions = run["net"], run["planner"], run["rng"], run["decisions"]
    n = run["n"]
    for e in range(run["epochs"], epochs):
        t = 30.0 * e
        for _ in range(rate):
            o, d = rng.choice(len(net.aerodrome_ids), 2, replace=False)
            planner.submit(FlightRequest(f"r{n:05d}", net.aerodrome_ids[o], net.aerodrome_ids[d],
                                         t, t, t + 60.0))
            n += 1
        for f in planner.plan(t, e).approved:
            decisions.append(f"{f.request_id}:{e}:{f.candidate_index}:{f.departure_s:.3f}:"
                             f"{' '.join(f.route_node_ids)}")
    run.update(epochs=epochs, n=n)
    _RUNS[(policy, backend, seed, rate)] = run
    digest = hashlib.sha256("\n".join(decisions).encode()).hexdigest()[:16]
    return n, len(decisions), digest


@pytest.mark.parametrize("policy, backend, approved, digest", [
    ("fifo", "greedy", 116, "fb38e85a131b1443"),
    ("mwis", "greedy", 148, "000402a8d4e6968c"),
    ("mwis", "exact", 153, "f9837fd6bdce7fd8"),
])
def test_paper_scenario_first_900_s_approvals_are_pinned(policy, backend, approved, digest):
    requests, got_approved, got_digest = _run(policy, backend, duration_s=900.0)
    assert requests == 300
    assert (got_approved, got_digest) == (approved, digest)


@pytest.mark.slow
@pytest.mark.parametrize("policy, backend, approved, digest", [
    ("fifo", "greedy", 342, "4c9399530bb824a3"),
    ("mwis", "greedy", 379, "751ff09b3062a846"),
    ("mwis", "exact", 408, "7d97eb2c7f9f39f1"),
])
def test_paper_scenario_3500_s_approvals_are_pinned(policy, backend, approved, digest):
    requests, got_approved, got_digest = _run(policy, backend)
    assert requests == 1170
    assert (got_approved, got_digest) == (approved, digest)
