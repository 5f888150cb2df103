"""The first-fit baseline in the in-process runner: a method like fifo, on identical demand."""

from uam_planner.planning import Planner
from uam_sim.world.demand import RequestGenerator
from uam_sim.studies.experiment import make_config, run_sweep
from uam_sim.runner.experiment_config import DEFAULT_METHODS
from uam_sim.runner.network_spec import load_network_spec
from uam_sim.runner.sweep import cell_params

NET = {"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}}


def test_firstfit_runs_in_the_sweep_and_matches_the_planner(tmp_path):
    assert "firstfit" in DEFAULT_METHODS
    cfg = make_config(dict(network=NET, methods=["fifo", "firstfit"], rates=[6], seeds=[0],
                           duration_s=300.0, out=str(tmp_path), workers=1, include_qpu=False,
                           tts={"enabled": False}))
    sweep = run_sweep(cfg, progress=False)
    ff = next(c for c in sweep.cells if c["summary"]["method"] == "firstfit")
    assert ff["audit"]["losses"] == 0 and ff["summary"]["approved"] > 0
    assert ff["instances"] == []  # baselines add no MWIS instances to the corpus
    # a baseline's cell key does not depend on the MWIS time limit
    assert "time_limit_s" not in cell_params(cfg, "firstfit", 6, 0)
    # the same approvals as a first-fit Planner fed the same requests
    net = load_network_spec(NET)
    p = Planner(net, cfg.planning_config("greedy", 0), policy="firstfit")
    gen = RequestGenerator(net.aerodrome_ids, 6, cfg.interval_s, cfg.window_s, 0)
    direct = []
    for e in range(10):
        for r in gen.requests_at(30.0 * e, e):
            p.submit(r)
        direct += [(f.request_id, e, f.candidate_index) for f in p.plan(30.0 * e, e).approved]
    assert [(f["request_id"], f["epoch"], f["candidate_index"]) for f in ff["flights"]] == direct
    assert any(ci > 0 for _, _, ci in direct)  # it used alternative candidates
    assert all(f["earliest_departure_s"] <= f["departure_s"] for f in ff["flights"])
