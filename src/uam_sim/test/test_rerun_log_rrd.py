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

from uam_sim.rerun_log import RerunLogger  # noqa: E402


def _cli() -> str | None:
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


def tiny_network():
    """Duck-typed Network: 2 aerodromes and 1 waypoint, 2 corridors."""
    return NS(enu_m=np.array([[0.0, 0.0, 5.0], [1000.0, 0.0, 120.0], [2000.0, 0.0, 5.0]]),
              edges=np.array([[0, 1], [1, 2]]), is_aerodrome=np.array([True, False, True]),
              names=("Aerodrome A", "W1", "Aerodrome B"), node_ids=("A", "W1", "B"))


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
    report = NS(header=NS(stamp=stamp(30.0)), approved=1, active_flights=1, vertices=3,
                instance=NS(selected=[0]), solve_time_s=0.01, pending_requests=2)
    logger.log_planning_report_msg(report)
    for k in range(3):
        state = NS(header=NS(stamp=stamp(31.0 + k)),
                   vehicles=[NS(vehicle_id="r1", position=point(20.0 * k, 0, 6))])
        logger.log_fleet_state_msg(state)
    logger.log_fleet_state_msg(NS(header=NS(stamp=stamp(34.0)), vehicles=[]))  # landed
    assert logger.approved_total == 1
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
    for entity in ("world/network/corridors", "world/network/aerodromes", "world/vehicles",
                   "world/routes/r1", "metrics/approved_cumulative", "metrics/solve_time_s"):
        assert entity in text, entity
    assert "sim_time" in text
    assert "world/routes/r2" not in text  # rejected plans draw no route


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


def test_levels_of_a_layered_network_are_drawn_and_routes_coloured_by_their_level():
    from uam_sim.rerun_log import LEVEL_COLORS, flight_level_index

    # hand-computed: climb from a 5 m pad to 90 m, cruise, descend: level 1 of (60, 90, 120)
    route = [[0, 0, 5], [0, 0, 90], [1000, 0, 90], [2000, 0, 90], [2000, 0, 5]]
    assert flight_level_index(route, (60.0, 90.0, 120.0)) == 1
    assert flight_level_index(route, ()) == -1
    logged = {}
    fake_rr = NS(LineStrips3D=lambda strips, **kw: ("strips", [np.asarray(x) for x in strips], kw),
                 Points3D=lambda *a, **kw: ("points", a, kw))
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
    assert kw["colors"][0] == LEVEL_COLORS[0] and kw["colors"][-1] == LEVEL_COLORS[2]
    logger.log_route(30.0, "r1", route)
    assert logged["world/routes/r1"][2]["colors"] == LEVEL_COLORS[1]
