"""Rerun logging into an .rrd file (no viewer): the file exists, verifies and holds our entities."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest

pytest.importorskip("rerun")

from uam_sim.views.rerun_log import RerunLogger  # noqa: E402


def _cli() -> str | None:
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


def tiny_network():
    """Duck-typed Network: 2 aerodromes and 1 waypoint, 2 corridors, near Singapore."""
    return NS(enu_m=np.array([[0.0, 0.0, 5.0], [1000.0, 0.0, 120.0], [2000.0, 0.0, 5.0]]),
              edges=np.array([[0, 1], [1, 2]]), is_aerodrome=np.array([True, False, True]),
              names=("Aerodrome A", "W1", "Aerodrome B"), node_ids=("A", "W1", "B"),
              origin_lat_lon_alt=(1.29, 103.85, 0.0))


def stamp(s: float):
    return NS(sec=int(s), nanosec=int(round((s - int(s)) * 1e9)))


def point(x, y, z):
    return NS(x=x, y=y, z=z)


@pytest.fixture(scope="module")
def rrd(tmp_path_factory) -> tuple[Path, RerunLogger]:
    path = tmp_path_factory.mktemp("rr") / "sub" / "run.rrd"
    logger = RerunLogger("save", path, network=tiny_network())
    plan = NS(outcome=0, request_id="r1", header=NS(stamp=stamp(30.0)),
              waypoints=[NS(position=point(0, 0, 5)), NS(position=point(1000, 0, 120)),
                         NS(position=point(2000, 0, 5))])
    rejected = NS(outcome=1, request_id="r2", header=NS(stamp=stamp(30.0)), waypoints=[])
    logger.log_flight_plan_msg(plan)
    logger.log_flight_plan_msg(rejected)
    # the decision panels (issue 21): operator a's requests a1 (earliest 0 s) approved at 30 s
    # and a2 (earliest 10 s) at 50 s, b's b1 expired; r1 had no request logged (no delay)
    for rid, op, earliest in (("a1", "a", 0.0), ("a2", "a", 10.0), ("b1", "b", 0.0)):
        logger.log_request_msg(NS(request_id=rid, operator_id=op, earliest_departure=stamp(earliest)))
    for rid, dep in (("a1", 30.0), ("a2", 50.0)):
        logger.log_flight_plan_msg(NS(outcome=0, request_id=rid, operator_id="a", header=NS(stamp=stamp(30.0)),
                                      departure_time=stamp(dep), waypoints=[]))
    logger.log_flight_plan_msg(NS(outcome=2, request_id="b1", operator_id="b", header=NS(stamp=stamp(30.0)),
                                  waypoints=[]))
    # approved 3 (r1, a1, a2), expired 1; delays 30, 40: mean 35, p95 = 30 + 0.95 x 10 = 39.5;
    # shares a 2 of 2, b 0 of 1
    assert logger.decision_values() == {"decisions/approved": 3.0, "decisions/expired": 1.0,
                                        "delay/p95_s": pytest.approx(39.5), "delay/mean_s": 35.0,
                                        "share/a": 1.0, "share/b": 0.0}
    report = NS(header=NS(stamp=stamp(30.0)), approved=1, active_flights=1, vertices=3,
                instance=NS(selected=[0]), solve_time_s=0.01, pending_requests=2)
    logger.log_planning_report_msg(report)
    for k in range(3):
        state = NS(header=NS(stamp=stamp(31.0 + k)),
                   vehicles=[NS(vehicle_id="r1", position=point(20.0 * k, 0, 6))])
        logger.log_fleet_state_msg(state)
    logger.log_fleet_state_msg(NS(header=NS(stamp=stamp(34.0)), vehicles=[]))  # landed
    assert logger.approved_total == 3
    logger.close()
    return path, logger


def test_rrd_file_is_written_and_non_empty(rrd):
    path, _ = rrd
    assert path.exists() and path.stat().st_size > 1000


@pytest.mark.skipif(_cli() is None, reason="rerun CLI not installed")
def test_rrd_verifies_and_contains_the_entities(rrd):
    path, _ = rrd
    verify = subprocess.run([_cli(), "rrd", "verify", str(path)], capture_output=True, text=True,
                            timeout=120)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    printed = subprocess.run([_cli(), "rrd", "print", "-vv", str(path)], capture_output=True, text=True,
                             timeout=120)
    assert printed.returncode == 0, printed.stderr
    text = printed.stdout + printed.stderr
    for entity in ("world/network/corridors", "world/network/aerodromes", "world/fleet",
                   "geo/network/corridors", "geo/fleet", "metrics/approved_cumulative",
                   "metrics/solve_time_s", "metrics/pending_requests", "metrics/decisions/expired",
                   "metrics/delay/p95_s", "metrics/share/a", "metrics/share/b"):
        assert entity in text, entity
    assert "sim_time" in text
    chunks = text.split("entity_path: ")
    fleet = "".join(c for c in chunks if c.startswith("/world/fleet"))
    # aircraft and their routes share the entity (instance k = aircraft k and its route)
    assert "Points3D:positions" in fleet and "LineStrips3D:strips" in fleet
    assert "GeoPoints:positions" in "".join(c for c in chunks if c.startswith("/geo/fleet"))
    assert "r2" not in fleet  # rejected plans draw no route
    # the blueprint travels in the file, with its views
    assert "Blueprint" in text
    data = subprocess.run([_cli(), "rrd", "print", "-vvv", str(path)], capture_output=True, text=True,
                          timeout=120).stdout
    for view in ("Network (top-down)", "Geographic", "Flights", "MWIS size", "Solve time [s]",
                 "Approvals and expiries", "Departure delay [s]", "Operator approval share"):
        assert view in data, view


def test_blueprint_lays_out_the_views():
    from uam_sim.views.rerun_log import make_blueprint, map_zoom, top_down_eye

    net = tiny_network()
    position, target = top_down_eye(net)
    assert target == (1000.0, 0.0, 0.0) and position[:2] == (1000.0, 0.0) and position[2] > 1000.0
    # at that web-map zoom the 2 km network spans the 200 px pane
    metres_per_px = 156543.03 * np.cos(np.radians(1.29)) / 2 ** map_zoom(net)
    assert 2000.0 / metres_per_px == pytest.approx(200.0)
    bp = make_blueprint(net)
    names = []

    def walk(part):
        names.append(str(getattr(part, "name", "")))
        for child in getattr(part, "contents", None) or []:
            walk(child)
    walk(bp.root_container)
    assert {"Network (top-down)", "Geographic", "Flights", "MWIS size [vertices]",
            "MWIS selected vertices", "Solve time [s]", "Approvals and expiries",
            "Departure delay [s]", "Operator approval share"} <= set(names)
    assert not any(n.startswith("Side") for n in names)  # one level: nothing to see from the side


def test_corridor_levels_colour_corridors_and_default_to_one_level():
    from uam_sim.views.rerun_log import LEVEL_COLORS, corridor_levels, level_colors

    net = tiny_network()
    assert corridor_levels(net).tolist() == [0, 0]
    net.corridor_levels = ["FL2", "FL1"]
    assert corridor_levels(net).tolist() == [1, 0]
    assert level_colors(corridor_levels(net)).tolist() == [list(LEVEL_COLORS[1]), list(LEVEL_COLORS[0])]
    net.corridor_levels = [1]
    with pytest.raises(ValueError, match="corridor_levels: 1 levels for 2 corridors"):
        corridor_levels(net)


def test_off_mode_does_nothing_and_bad_mode_is_refused(tmp_path):
    logger = RerunLogger("off")
    logger.log_fleet(1.0, ["a"], [[0, 0, 0]])
    logger.close()
    assert not logger.enabled and list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="'live'"):
        RerunLogger("live")
    with pytest.raises(ValueError, match="rrd_path"):
        RerunLogger("save")


def test_mismatched_ids_and_positions_are_refused(tmp_path):
    logger = RerunLogger("save", tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="2 ids for 1 positions"):
        logger.log_fleet(0.0, ["a", "b"], [[0, 0, 0]])
    logger.close()


@pytest.mark.skipif(_cli() is None, reason="rerun CLI not installed")
def test_a_recording_becomes_an_rrd_with_the_view(tmp_path):
    """``python -m uam_sim.rerun_log RUN.mcap --network NET`` for runs recorded without Rerun."""
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from uam_sim.views.rerun_log import main
    from view_runs import TINY, record_run

    mcap = tmp_path / "run.mcap"
    record_run(mcap, "greedy", duration_s=60.0, views=False)
    assert main([str(mcap), "--network", str(TINY)]) == 0
    rrd = mcap.with_suffix(".rrd")
    text = subprocess.run([_cli(), "rrd", "print", "-vv", str(rrd)], capture_output=True, text=True,
                          timeout=120).stdout
    for entity in ("/world/network/corridors", "/world/fleet", "/geo/fleet", "/metrics/approved_cumulative"):
        assert f"entity_path: {entity}" in text, entity
    assert main([str(tmp_path / "missing.mcap")]) == 1
def test_levels_of_a_layered_network_are_drawn_in_their_colours():
    from uam_sim.views.rerun_log import LEVEL_COLORS, flight_level_index

    # hand-computed: climb from a 5 m pad to 90 m, cruise, descend: level 1 of (60, 90, 120)
    route = [[0, 0, 5], [0, 0, 90], [1000, 0, 90], [2000, 0, 90], [2000, 0, 5]]
    assert flight_level_index(route, (60.0, 90.0, 120.0)) == 1
    assert flight_level_index(route, ()) == -1
    logged = {}
    fake_rr = NS(LineStrips3D=lambda strips, **kw: ("strips", [np.asarray(x) for x in strips], kw),
                 Points3D=lambda *a, **kw: ("points", a, kw),
                 GeoLineStrings=lambda **kw: ("geo-strips", kw), GeoPoints=lambda *a, **kw: ("geo-points", a, kw))
    logger = RerunLogger("off")
    logger._rr = fake_rr
    logger._rec = NS(log=lambda entity, arch, static=False: logged.__setitem__(entity, arch),
                     set_time=lambda *a, **kw: None)
    net = tiny_network()
    net.levels_m = (60.0, 90.0, 120.0)
    logger.log_network(net)
    _, strips, kw = logged["world/network/corridors"]
    assert len(strips) == 3 * 2  # 2 corridors at each of 3 levels
    assert sorted({float(s[0, 2]) for s in strips}) == [60.0, 90.0, 120.0]
    assert all(s[0, 2] == s[1, 2] for s in strips)
    assert tuple(kw["colors"][0]) == LEVEL_COLORS[0] and tuple(kw["colors"][-1]) == LEVEL_COLORS[2]
    # the side view's copy: the same corridors, heights exaggerated so the levels lie apart
    from uam_sim.views.rerun_log import height_exaggeration, make_blueprint
    k = height_exaggeration(net)
    assert k == pytest.approx(0.25 * 2000.0 / 120.0)  # a quarter of the 2 km extent over 120 m
    _, side, side_kw = logged["side/network/corridors"]
    assert sorted({float(s[0, 2]) for s in side}) == pytest.approx([60.0 * k, 90.0 * k, 120.0 * k])
    assert [tuple(c) for c in side_kw["colors"]] == [tuple(c) for c in kw["colors"]]
    names = []

    def walk(part):
        names.append(str(getattr(part, "name", "")))
        for child in getattr(part, "contents", None) or []:
            walk(child)
    walk(make_blueprint(net).root_container)
    assert f"Side (from the south, heights x{k:.0f})" in names
    # the side view names each level by its height, at that height
    _, (level_pts,), level_kw = logged["side/network/levels"]
    assert level_kw["labels"] == ["60 m", "90 m", "120 m"] and level_kw["show_labels"] is True
    assert [p[2] for p in level_pts] == pytest.approx([60.0 * k, 90.0 * k, 120.0 * k])
    # a constraint is drawn in the side view too, its band's heights exaggerated as the levels
    from uam_planner.constraints import Constraint
    disk = Constraint("disk", 1, "", 0.0, 100.0, center_m=(1000.0, 0.0), radius_m=200.0, lower_m=50.0, upper_m=100.0)
    logger.log_constraints(10.0, [disk])
    _, top, _ = logged["world/constraints/disk"]
    _, drawn, _ = logged["side/constraints/disk"]
    assert len(drawn) == len(top)
    assert sorted({round(float(z), 6) for s in drawn for z in s[:, 2]}) == pytest.approx([50.0 * k, 100.0 * k])


def _latest_at(path, entity: str) -> dict[float, dict]:
    """What the viewer shows of ``entity`` at each logged sim_time [s]: every component's latest
    value at or before that time (static values for all times), read back from the .rrd."""
    import rerun as rr

    rows = []           # (time s or None for static, order, component, value)
    order = 0
    for chunk in rr.chunk.RrdReader(path).stream():
        if chunk.entity_path != entity:
            continue
        data = chunk.to_record_batch().to_pydict()
        times = [None] * chunk.num_rows if chunk.is_static else [t.total_seconds() for t in data["sim_time"]]
        for i, t in enumerate(times):
            for name, values in data.items():
                if ":" in name:
                    rows.append((t, order, name, values[i]))
                    order += 1
    static = {name: v for t, _, name, v in rows if t is None}
    out = {}
    for t in sorted({t for t, *_ in rows if t is not None}):
        state = dict(static)
        for _t, _o, name, v in sorted((r for r in rows if r[0] is not None and r[0] <= t),
                                      key=lambda r: (r[0], r[1])):
            state[name] = v
        out[t] = state
    return out


@pytest.mark.parametrize("batch_steps", [1, 4, 50])
def test_batched_fleet_logging_shows_every_step_as_logged(tmp_path, batch_steps):
    """However the positions are batched (send_columns), at every step the viewer shows that
    step's positions with their labels, the aircraft colour and size, and the routes of exactly
    the airborne flights (instance k = aircraft k), on the map too; close() sends the rest."""
    from uam_sim.views.rerun_log import ROUTE_COLOR, VEHICLE_COLOR, VEHICLE_RADIUS_UI

    path = tmp_path / "f.rrd"
    rng = np.random.default_rng(3)
    steps = []
    with RerunLogger("save", path, network=tiny_network(), batch_steps=batch_steps, batch_wall_s=60.0) as lg:
        lg.log_route(0.0, "a", [[0, 0, 5], [1000, 0, 120], [2000, 0, 5]])
        for k in range(11):
            ids = ["a", "b"] if k < 4 else (["b"] if k < 7 else ([] if k < 8 else ["c", "b"]))
            pos = rng.uniform(0, 2000, size=(len(ids), 3))
            lg.log_fleet(float(k), ids, pos)
            steps.append((float(k), ids, pos))
    shown = _latest_at(path, "/world/fleet")
    geo = _latest_at(path, "/geo/fleet")
    rgba = int.from_bytes(bytes(VEHICLE_COLOR) + b"\xff", "big")
    for t, ids, pos in steps:
        s = shown[t]
        np.testing.assert_allclose(np.asarray(s["Points3D:positions"]).reshape(-1, 3), pos, rtol=1e-6)
        assert s["Points3D:labels"] == ids
        assert s["Points3D:colors"] == [rgba] and s["Points3D:radii"] == [-VEHICLE_RADIUS_UI]
        assert s["Points3D:show_labels"] == [False]
        strips = s["LineStrips3D:strips"]
        assert len(strips) == len(ids)
        for vid, p, strip in zip(ids, pos, strips):
            if vid == "a":
                assert np.asarray(strip).shape == (3, 3)
            else:  # no route known: a point-sized strip at the aircraft
                assert np.asarray(strip).shape == (2, 3)
        assert s["LineStrips3D:colors"] == [int.from_bytes(bytes(ROUTE_COLOR), "big")]
        assert len(geo[t]["GeoPoints:positions"]) == len(ids)
        if ids:
            assert -90 < geo[t]["GeoPoints:positions"][0][0] < 90


def test_the_scenario_clock_and_the_constraints_are_in_the_rrd(tmp_path):
    """Issue 22: with the scenario's UTC start the fleet is on a ``utc`` timeline too (t = 3 s is
    2025-01-06T00:00:03Z), and a constraint set logged at t = 30 s draws each constraint from then
    (a square: 2 rings of 4 sides + 4 vertical edges = 6 strips) until its window ends (a clear at
    end_s = 100 s); a constraint missing from the next set is cleared then (t = 60 s)."""
    import rerun as rr
    from uam_planner.constraints import Constraint

    path = tmp_path / "c.rrd"
    square = Constraint("sq", 1, "event", 0.0, 100.0, lower_m=0.0, upper_m=300.0,
                        rings_m=(np.array([[-100.0, -100.0], [100.0, -100.0], [100.0, 100.0], [-100.0, 100.0]]),))
    closed = Constraint("B-closed", 1, "", 0.0, 1e9, vertiport_id="B")
    with RerunLogger("save", path, network=tiny_network(), utc_zero_ns=1_736_121_600 * 10**9) as lg:
        lg.log_fleet(3.0, ["a"], [[0.0, 0.0, 5.0]])
        lg.log_constraints(30.0, [square, closed])
        lg.log_constraints(60.0, [square])
        lg.log_fleet(120.0, ["a"], [[0.0, 0.0, 5.0]])  # the run reaches the square's end
    by_entity: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(path).stream():
        if not chunk.is_static:
            by_entity.setdefault(chunk.entity_path, []).append(chunk.to_record_batch().to_pydict())
    fleet = [d for d in by_entity["/world/fleet"] if "Points3D:positions" in d]
    assert [str(t) for d in fleet for t in d["utc"]] == ["2025-01-06 00:00:03", "2025-01-06 00:02:00"]
    rows = [(t.total_seconds(), name) for d in by_entity["/world/constraints/sq"] for k, t in enumerate(d["sim_time"])
            for name in d if ":" in name and d[name][k] is not None]
    assert (30.0, "LineStrips3D:strips") in rows and any(t == 100.0 and "Clear" in n for t, n in rows), rows
    strips = next(d["LineStrips3D:strips"][0] for d in by_entity["/world/constraints/sq"] if "LineStrips3D:strips" in d)
    assert len(strips) == 6
    closure = [(t.total_seconds(), name) for d in by_entity["/world/constraints/B-closed"]
               for k, t in enumerate(d["sim_time"]) for name in d if ":" in name and d[name][k] is not None]
    assert (30.0, "LineStrips3D:strips") in closure and any(t == 60.0 and "Clear" in n for t, n in closure), closure
    assert "/geo/constraints/sq" in by_entity


def test_a_constraint_window_past_the_runs_end_keeps_the_timeline_to_the_run(tmp_path):
    """A 900 s run with a constraint until 3,600 s: nothing is logged after the run's last moment
    (the viewer's time cursor follows the newest data: logged at the window's end, the view opened
    at +3,600 s with the constraint cleared), and the constraint is drawn from its start."""
    import rerun as rr
    from uam_planner.constraints import Constraint

    path = tmp_path / "late.rrd"
    storm = Constraint("storm", 1, "storm", 240.0, 3600.0, center_m=(0.0, 0.0), radius_m=150.0,
                       lower_m=0.0, upper_m=500.0)
    with RerunLogger("save", path, network=tiny_network(), batch_steps=1) as lg:
        lg.log_fleet(0.0, ["a"], [[0.0, 0.0, 5.0]])
        lg.log_constraints(30.0, [storm])
        for t in (30.0, 300.0, 900.0):
            lg.log_fleet(t, ["a"], [[t, 0.0, 5.0]])
    times, drawn = [], []
    for chunk in rr.chunk.RrdReader(path).stream():
        if chunk.is_static:
            continue
        d = chunk.to_record_batch().to_pydict()
        times += [t.total_seconds() for t in d.get("sim_time", [])]
        if chunk.entity_path == "/world/constraints/storm":
            drawn += [(t.total_seconds(), "LineStrips3D:strips" in d) for t in d["sim_time"]]
    assert max(times) == 900.0, sorted(set(times))
    assert drawn == [(240.0, True)], drawn


def test_graph_routes_match_their_aircraft_and_replanned_ones_show_as_such(tmp_path):
    """In the node graph the simulator names a vehicle operator/request: its route must carry that
    key (it carried the bare request id, so every airborne route was drawn as a point). A plan
    version > 1 (issue 22) replaces the route, in the re-planned colour, and is not an approval."""
    from uam_sim.views.rerun_log import REPLANNED_ROUTE_COLOR, ROUTE_COLOR

    def plan(version, xs, stamp_s):
        return NS(outcome=0, operator_id="generator", request_id="r1", version=version, header=NS(stamp=stamp(stamp_s)),
                  waypoints=[NS(position=point(x, 0, 100)) for x in xs])

    path = tmp_path / "g.rrd"
    with RerunLogger("save", path, network=tiny_network(), batch_steps=1) as lg:
        lg.log_flight_plan_msg(plan(1, (0, 1000, 2000), 0.0))
        lg.log_fleet(1.0, ["generator/r1"], [[10.0, 0.0, 100.0]])
        lg.log_flight_plan_msg(plan(2, (10, 500), 30.0))
        lg.log_fleet(31.0, ["generator/r1"], [[20.0, 0.0, 100.0]])
        assert lg.approved_total == 1
    shown = _latest_at(path, "/world/fleet")
    assert np.asarray(shown[1.0]["LineStrips3D:strips"][0]).shape == (3, 3)
    assert shown[1.0]["LineStrips3D:colors"] == [int.from_bytes(bytes(ROUTE_COLOR), "big")]
    assert np.asarray(shown[31.0]["LineStrips3D:strips"][0]).shape == (2, 3)
    assert shown[31.0]["LineStrips3D:colors"] == [int.from_bytes(bytes(REPLANNED_ROUTE_COLOR) + b"\xff", "big")]


def _panel_sizes(part, width: float, height: float, out: dict) -> dict:
    """Size in UI points of each view of a blueprint laid out in ``width`` x ``height``: the
    containers' shares (equal when unset) split the space; a grid fills rows of its columns."""
    if not hasattr(part, "kind"):   # a view, not a container
        out[str(part.name)] = (width, height)
        return out
    contents, kind = list(part.contents), str(part.kind)
    if "Horizontal" in kind:
        shares = np.asarray(part.column_shares or [1.0] * len(contents), dtype=float)
        for child, s in zip(contents, shares / shares.sum()):
            _panel_sizes(child, width * s, height, out)
    elif "Vertical" in kind:
        shares = np.asarray(part.row_shares or [1.0] * len(contents), dtype=float)
        for child, s in zip(contents, shares / shares.sum()):
            _panel_sizes(child, width, height * s, out)
    else:
        assert "Grid" in kind, kind
        rows = -(-len(contents) // part.grid_columns)
        for child in contents:
            _panel_sizes(child, width / part.grid_columns, height / rows, out)
    return out


def test_the_metric_panels_are_readable_at_1400x800():
    """At 1400x800 (about 730 points under the top bar, above the time panel) every metric panel
    is tall and wide enough for the y axis's values beside its legend (eight panels stacked in one
    column had ~90 points each); a multi-series legend sits in a corner, the shares on a fixed
    0..1 axis."""
    from uam_sim.views.rerun_log import make_blueprint

    bp = make_blueprint(tiny_network())
    sizes = _panel_sizes(bp.root_container, 1400.0, 730.0, {})
    plots = {n: wh for n, wh in sizes.items() if n not in ("Network (top-down)", "Geographic")}
    assert len(plots) == 7, sorted(sizes)
    assert all(w >= 250 and h >= 150 for w, h in plots.values()), plots
    views = {}

    def walk(part):
        views[str(getattr(part, "name", ""))] = part
        for child in part.contents if hasattr(part, "kind") else ():
            walk(child)
    walk(bp.root_container)
    for name in ("Flights", "Approvals and expiries", "Departure delay [s]", "Operator approval share"):
        legend = views[name].properties["PlotLegend"]
        assert legend.corner is not None and legend.visible is None, name
    share_range = views["Operator approval share"].properties["ScalarAxis"].range.as_arrow_array().to_pylist()[0]
    assert share_range[0] <= 0.0 and share_range[1] >= 1.0, share_range


def test_crowded_vertiport_labels_are_thinned_and_every_vertiport_is_drawn():
    """Four vertiports within 400 m in the middle of a 20 km network: one keeps its label (the
    one with most corridors), the others are drawn unlabelled, with their full names for hover;
    the two far apart keep theirs. Names lose their parenthesised part on the map."""
    from uam_sim.views.rerun_log import LABEL_CHAR_PX, LABEL_LINE_PX, LABEL_VIEW_PX

    xy = [(-10000.0, 0.0), (10000.0, 0.0), (0.0, 0.0), (300.0, 100.0), (-200.0, -150.0), (100.0, 350.0)]
    names = ("West Port", "East Port", "Centre (Downtown)", "Centre North", "Centre South", "Centre Quay")
    net = NS(enu_m=np.array([(x, y, 5.0) for x, y in xy]), is_aerodrome=np.ones(6, dtype=bool),
             edges=np.array([[3, 0], [3, 1], [3, 2], [0, 2]]), names=names,
             node_ids=tuple(f"V{i}" for i in range(6)), origin_lat_lon_alt=(1.29, 103.85, 0.0))
    logged = {}
    fake_rr = NS(LineStrips3D=lambda *a, **kw: ("strips", a, kw), Points3D=lambda pts, **kw: (np.asarray(pts), kw),
                 GeoLineStrings=lambda **kw: kw, GeoPoints=lambda *a, **kw: kw)
    logger = RerunLogger("off")
    logger._rr = fake_rr
    logger._rec = NS(log=lambda entity, arch, static=False: logged.__setitem__(entity, arch))
    logger.log_network(net)
    pts, kw = logged["world/network/aerodromes/labelled"]
    assert kw["show_labels"] is True and sorted(kw["labels"]) == ["Centre North", "East Port", "West Port"]
    hidden, hkw = logged["world/network/aerodromes/unlabelled"]
    assert hkw["show_labels"] is False and sorted(hkw["labels"]) == ["Centre (Downtown)", "Centre Quay", "Centre South"]
    assert len(pts) + len(hidden) == 6
    # no two shown labels' boxes (centred on their anchors, at the view's scale) overlap
    m_per_px = 20000.0 / LABEL_VIEW_PX
    for i in range(len(pts)):
        for j in range(i + 1, len(pts)):
            half_widths = (len(kw["labels"][i]) + len(kw["labels"][j])) * LABEL_CHAR_PX * m_per_px / 2
            assert (abs(pts[i, 0] - pts[j, 0]) >= half_widths
                    or abs(pts[i, 1] - pts[j, 1]) >= LABEL_LINE_PX * m_per_px), (kw["labels"][i], kw["labels"][j])
