"""A short run's .rrd opened in the real Rerun viewer, headless, and judged from its screenshot.

The viewer is the binary in the rerun-sdk wheel (``rerun``), run under Xvfb and rendering with
Mesa's software Vulkan (lavapipe); scripts/setup.sh installs both when missing. ``--screenshot-to``
makes the viewer save one frame and quit. The recording ends with aircraft in the air, and the
blueprint puts the time cursor on the newest data, so the frame shows them.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from uam_sim.views.rerun_log import (AERODROME_COLOR, CORRIDOR_COLOR, LEVEL_COLORS, ROUTE_COLOR,  # noqa: E402
                               VEHICLE_COLOR)
from view_runs import ROOT, record_run  # noqa: E402

SINGAPORE = ROOT / "config" / "networks" / "singapore.yaml"
SINGAPORE_LAYERED = ROOT / "config" / "networks" / "singapore-layered.yaml"

pytestmark = pytest.mark.slow

WINDOW = (1400, 800)


def _cli() -> str:
    exe = Path(sys.executable).with_name("rerun")
    found = str(exe) if exe.exists() else shutil.which("rerun")
    assert found, "the rerun CLI of rerun-sdk is not installed (scripts/setup.sh installs it)"
    return found


@pytest.fixture(scope="module")
def xvfb_display():
    """A private X display (Xvfb picks a free number and tells it through a pipe).

    The screen is larger than twice the window, so that the pointer, which starts at the centre
    of the screen, is outside the window and no hover tooltip covers the view."""
    xvfb = shutil.which("Xvfb")
    assert xvfb, "Xvfb is not installed (scripts/setup.sh installs the Debian package xvfb)"
    r, w = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(w), "-screen", "0", "4000x3000x24", "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    try:
        with os.fdopen(r) as f:
            number = f.readline().strip()
        assert number, "Xvfb did not report a display number"
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def screenshot(path: Path, out: Path, display: str, tmp: Path) -> np.ndarray:
    env = dict(os.environ, DISPLAY=display, XDG_RUNTIME_DIR=str(tmp))
    env.pop("WAYLAND_DISPLAY", None)   # force X11 (Xvfb)
    cmd = [_cli(), str(path), "--port", str(_free_port()), "--screenshot-to", str(out),
           "--window-size", f"{WINDOW[0]}x{WINDOW[1]}"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert done.returncode == 0 and out.exists(), done.stdout[-3000:] + done.stderr[-3000:]
    from PIL import Image
    return np.asarray(Image.open(out).convert("RGB")).astype(np.int16)


def near(img: np.ndarray, rgb, tol: int = 12) -> np.ndarray:
    return (np.abs(img - np.asarray(rgb[:3], dtype=np.int16)) <= tol).all(axis=-1)


@pytest.fixture(scope="module")
def shot(tmp_path_factory, xvfb_display):
    tmp = tmp_path_factory.mktemp("viewer")
    rrd = tmp / "run.rrd"
    # a run on the city-scale network (~40 km across, where a 30 m sphere is below one pixel), cut
    # at 200 s while flights are airborne (as a live viewer sees it mid-run)
    from uam_planner.network import load_network
    net = load_network(SINGAPORE)
    record_run(tmp / "run.mcap", "greedy", network=net, rate=4.0, duration_s=240.0, views=False,
               rerun_rrd=rrd, stop_s=200)
    img = screenshot(rrd, tmp / "shot.png", xvfb_display, tmp)
    return img, rrd


def test_viewer_shows_aircraft_and_corridors_in_the_top_down_view(shot):
    img, _ = shot
    h, w, _ = img.shape
    # The top-down view is the left ~60 % of the window, below the top bar, above the time panel.
    left = img[int(0.06 * h):int(0.95 * h), :int(0.58 * w)]
    right = img[int(0.06 * h):int(0.35 * h), int(0.62 * w):]   # the geographic view
    scale = w / WINDOW[0]                                         # screenshots are in physical pixels
    aircraft = near(left, VEHICLE_COLOR)
    corridors = near(left, CORRIDOR_COLOR)
    vertiports = near(left, AERODROME_COLOR)
    # Aircraft are discs of 5 UI points radius: ~80 UI points^2 each; ask for at least 5 aircraft.
    assert aircraft.sum() >= 5 * 40 * scale ** 2, f"aircraft pixels: {aircraft.sum()}"
    assert vertiports.sum() >= 3 * 20 * scale ** 2, f"vertiport pixels: {vertiports.sum()}"
    assert corridors.sum() >= 3000 * scale ** 2, f"corridor pixels: {corridors.sum()}"
    # The camera frames the whole network: corridor pixels span most of the view.
    ys, xs = np.nonzero(corridors)
    assert np.ptp(xs) > 0.5 * left.shape[1] and np.ptp(ys) > 0.5 * left.shape[0]
    # The aircraft sit on the network (within its drawn extent), not elsewhere in the view.
    ay, ax = np.nonzero(aircraft)
    assert xs.min() - 20 <= ax.min() and ax.max() <= xs.max() + 20
    assert ys.min() - 20 <= ay.min() and ay.max() <= ys.max() + 20
    # The geographic view beside it draws the fleet too.
    assert near(right, VEHICLE_COLOR).sum() >= 3 * 20 * scale ** 2
    # The airborne flights' routes show over the corridors (none did: thin, translucent, below
    # the corridors' width).
    routes = near(left, ROUTE_COLOR)
    assert routes.sum() >= 2000 * scale ** 2, f"route pixels: {routes.sum()}"


@pytest.fixture(scope="module")
def layered_shot(tmp_path_factory, xvfb_display):
    tmp = tmp_path_factory.mktemp("viewer_layered")
    rrd = tmp / "run.rrd"
    from uam_planner.network import load_network
    net = load_network(SINGAPORE_LAYERED)
    record_run(tmp / "run.mcap", "greedy", network=net, rate=4.0, duration_s=240.0, views=False,
               rerun_rrd=rrd, stop_s=200)
    return screenshot(rrd, tmp / "shot.png", xvfb_display, tmp)


def test_a_layered_network_shows_its_flight_levels_apart_and_the_routes(layered_shot):
    """Top-down, the four levels overlap and only the top one's colour shows: the side view
    below it shows each level in its colour."""
    img = layered_shot
    h, w, _ = img.shape
    scale = w / WINDOW[0]
    side = img[int(0.76 * h):int(0.95 * h), :int(0.58 * w)]      # the side view, under the top-down one
    top = img[int(0.06 * h):int(0.72 * h), :int(0.58 * w)]
    per_level = [int(near(side, c).sum()) for c in LEVEL_COLORS[:4]]
    assert sum(n >= 300 * scale ** 2 for n in per_level) >= 2, f"level colour pixels: {per_level}"
    assert all(n >= 100 * scale ** 2 for n in per_level), f"level colour pixels: {per_level}"
    # each level lies at its own height: the colours' rows do not coincide
    rows = [np.median(np.nonzero(near(side, c))[0]) for c in LEVEL_COLORS[:4]]
    assert len({round(r / (4 * scale)) for r in rows}) == 4, rows
    assert near(top, ROUTE_COLOR).sum() >= 1000 * scale ** 2, "no route lines in the top-down view"
