"""Per-run flight statistics (route length, detour over the shortest route, departure delay,
corridor use) from a run's approved flights, for the experiment report and the analysis of a
recording alike. numpy only: no plotting library is imported."""

from __future__ import annotations

import numpy as np


def corridor_use_m(network, flights) -> np.ndarray:
    """Flown distance per corridor [m] of a run's flights (each flight's route node ids)."""
    use = np.zeros(network.n_edges, dtype=float)
    L = np.asarray(network.edge_length_m)
    for f in flights:
        ids = f["route"].split()
        idx = [network.node_index(x) for x in ids]
        for a, b in zip(idx[:-1], idx[1:]):
            e = network.edge_index(a, b)
            use[e] += L[e]
    return use


def flight_metrics(cell, network=None, top=None) -> dict:
    """Per-run flight statistics: mean route length [m], mean detour [%] (route length over the
    shortest route of the same origin-destination pair, from the weight d*/d: d/d* = 1/w), mean
    delay [s] (departure - earliest departure), shares of flights on candidate 0 and with a
    delay, and the share of flown distance on the central corridors (``top`` mask) when a
    network is given."""
    fl = cell.get("flights") or []
    if not fl:
        return {}
    length = np.array([f["length_m"] for f in fl], dtype=float)
    weight = np.array([f["weight"] for f in fl], dtype=float)
    # a weight outside (0, 1] is not a planner's (e.g. a plan written by hand): no detour from it
    detour = 100.0 * (1.0 / weight[(weight > 0) & (weight <= 1)] - 1.0)
    delay = np.array([f["departure_s"] - f["earliest_departure_s"] for f in fl
                      if f.get("earliest_departure_s") not in (None, "")], dtype=float)
    out = {"flights": len(fl), "route_length_mean_m": float(length.mean()),
           "flown_km": float(length.sum() / 1000.0),
           "detour_mean_pct": float(detour.mean()) if detour.size else float("nan"),
           "shortest_share": float(np.mean([int(f["candidate_index"]) == 0 for f in fl])),
           "delay_mean_s": float(delay.mean()) if delay.size else float("nan"),
           "delayed_share": float((delay > 1e-6).mean()) if delay.size else float("nan")}
    if network is not None and top is not None:
        use = corridor_use_m(network, fl)
        out["central_share"] = float(use[top].sum() / use.sum()) if use.sum() > 0 else float("nan")
    return out
