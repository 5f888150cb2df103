"""A demand where planning the next epochs jointly pays (issue 21, item 6), constructed: every 30 s,
``--pairs`` random origin-destination pairs (seeded), each asked twice at once: a flexible
request of priority class 1 (it may depart now or at the next epoch: window [t, t + 30 s]) and
an urgent one of class 0 (window [t, t]). Two departures from one aerodrome at one time always
conflict, so the myopic planner (H = 1) with objective ``priority`` serves the class-1 request now
and the class-0 one expires; with H >= 2 one graph over both epochs sends the urgent request now
and the flexible one at the next epoch. It is the hand-computed case of
``test_planning_two_epochs_jointly_approves_more_than_two_myopic_epochs`` at scale, through the
in-process runner on the Singapore network (paper airspace, exact backend), with its audit.

    python scripts/horizon_payoff.py [--pairs 5] [--duration 900] [--seeds 0,1,2] [--horizons 1,2,3]
"""

from __future__ import annotations

import argparse

import numpy as np


class PairedDemand:
    """``requests_at`` as the runner's demand: per interval, pairs of (flexible class 1, urgent
    class 0) requests on one seeded origin-destination pair."""

    def __init__(self, aerodromes, pairs: int, seed: int, epoch_s: float = 30.0):
        self.aerodromes, self.pairs, self.seed, self.epoch_s = list(aerodromes), int(pairs), int(seed), float(epoch_s)

    def requests_at(self, t_s: float, interval_index: int):
        from uam_planner.planning import FlightRequest
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, int(interval_index)]))
        # distinct origins in one interval: the pairs conflict only within themselves
        origins = rng.choice(len(self.aerodromes), self.pairs, replace=False)
        out = []
        for j, o in enumerate(origins.tolist()):
            d = int(rng.choice([k for k in range(len(self.aerodromes)) if k != o]))
            a, b = self.aerodromes[o], self.aerodromes[d]
            out.append(FlightRequest(f"i{interval_index}-{j}-flex", a, b, t_s, t_s, t_s + self.epoch_s, priority=1))
            out.append(FlightRequest(f"i{interval_index}-{j}-urgent", a, b, t_s, t_s, t_s, priority=0))
        return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--horizons", default="1,2,3")
    ap.add_argument("--backend", default="exact")
    a = ap.parse_args(argv)
    from uam_planner.network import load_network
    from uam_sim.runner.experiment_config import make_config, resolve_path
    from uam_sim.runner.scenario import run_scenario
    print("| seed | H | requests | approved | expired | delay mean [s] | min separation [m] | losses | fallbacks |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed in (int(s) for s in a.seeds.split(",")):
        for h in (int(x) for x in a.horizons.split(",")):
            cfg = make_config(objective="priority", horizon_epochs=h, time_limit_s=5.0, workers=1)
            net = load_network(resolve_path(cfg.network))
            r = run_scenario(net, a.backend, 2 * a.pairs, seed, a.duration, cfg,
                             demand=PairedDemand(net.aerodrome_ids, a.pairs, seed))
            s = r.summary
            print(f"| {seed} | {h} | {s['requests']} | {s['approved']} | {s['expired']} | "
                  f"{s['delay_mean_s']:.1f} | {s['min_separation_m']:.1f} | {s['losses']} | {s['fallbacks']} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
