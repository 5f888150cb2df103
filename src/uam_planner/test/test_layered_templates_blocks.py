"""A pair's layered route templates, built a route's levels at a time, are exactly the templates
built one at a time (the reference below is the one-at-a-time construction): same waypoints, times
and segment arrays bit for bit, same order, read-only."""

import numpy as np
import pytest

from uam_planner.candidates import CandidateCache, RouteTemplate
from uam_planner.synthetic import generate_network


def one_at_a_time(cache, o, d, routes):
    net = cache.network
    xy = net.enu_m[:, :2]
    alt = net.lat_lon_alt[:, 2]
    pads_o, pads_d = net.pads_of(o), net.pads_of(d)
    out = []
    for li in cache.allowed_levels(o, d):
        level = float(net.levels_m[li])
        po = xy[o] + pads_o[li % len(pads_o)]
        pd = xy[d] + pads_d[li % len(pads_d)]
        for r in routes:
            mid = xy[np.asarray(r.node_indices[1:-1], dtype=np.int64)].reshape(-1, 2)
            horiz = np.concatenate(([po], mid, [pd]))
            pts = np.concatenate(([(po[0], po[1], alt[o])],
                                  np.column_stack((horiz, np.full(horiz.shape[0], level))),
                                  [(pd[0], pd[1], alt[d])]))
            legs = np.linalg.norm(np.diff(horiz, axis=0), axis=1)
            dur = np.concatenate(([(level - alt[o]) / cache.climb_rate_mps], legs / cache.speed_mps,
                                  [(level - alt[d]) / cache.descent_rate_mps]))
            rel = np.concatenate(([0.0], np.cumsum(dur)))
            v = (pts[1:] - pts[:-1]) / (rel[1:] - rel[:-1])[:, None]
            out.append(RouteTemplate(r, tuple(net.node_ids[i] for i in r.node_indices), pts, rel,
                                     (rel[:-1], rel[1:], pts[:-1], v), li, level))
    return out


@pytest.mark.parametrize("spec", [
    dict(n_nodes=300, n_aerodromes=40, levels_m=[60.0, 90.0, 120.0, 150.0], pads_per_vertiport=4),
    dict(n_nodes=300, n_aerodromes=60, extent_m=9000.0, pads_per_vertiport=3,
         levels_m=[60.0 + 30.0 * k for k in range(11)]),
    dict(n_nodes=200, n_aerodromes=30, levels_m=[90.0, 120.0, 150.0], pads_per_vertiport=1,
         direction_rule="none"),
])
def test_block_templates_equal_one_at_a_time(spec):
    net = generate_network(seed=3, **spec)
    cache = CandidateCache(net, speed_mps=23.0, climb_rate_mps=3.0, descent_rate_mps=2.5)
    ai = [int(i) for i in net.aerodrome_indices]
    rng = np.random.default_rng(0)
    for _ in range(25):
        o, d = (int(x) for x in rng.choice(ai, 2, replace=False))
        got = cache.templates(o, d)
        want = one_at_a_time(cache, o, d, cache.routes(o, d)[:len(got) // len(cache.allowed_levels(o, d))])
        assert len(got) == len(want)
        for g, w in zip(got, want):
            assert (g.route, g.node_ids, g.level_index, g.level_m) == \
                (w.route, w.node_ids, w.level_index, w.level_m)
            for a, b in zip((g.points_m, g.rel_times_s, *g.segments_rel),
                            (w.points_m, w.rel_times_s, *w.segments_rel)):
                assert a.shape == b.shape and a.tobytes() == b.tobytes()
                assert not a.flags.writeable and a.flags.c_contiguous == b.flags.c_contiguous
            tr_g, tr_w = g.trajectory(1234.5), w.trajectory(1234.5)
            assert tr_g.times_s.tobytes() == tr_w.times_s.tobytes()
