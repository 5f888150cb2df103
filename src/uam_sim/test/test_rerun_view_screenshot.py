"""A short run's .rrd opened in the real Rerun viewer, headless, and judged from its screenshot.

The viewer runs headless as :mod:`uam_sim.views.screenshot` runs it (Xvfb, Mesa's software
Vulkan, ``--screenshot-to``). The recording ends with aircraft in the air, and the blueprint puts
the time cursor on the newest data, so the frame shows them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from uam_sim.views.rerun_log import (AERODROME_COLOR, CORRIDOR_COLOR, LEVEL_COLORS, ROUTE_COLOR,  # noqa: E402
                               VEHICLE_COLOR)
from uam_sim.views.screenshot import WINDOW, screenshot as render, xvfb_display as private_display  # noqa: E402
from view_runs import ROOT, record_run  # noqa: E402

SINGAPORE = ROOT / "config" / "networks" / "singapore.yaml"
SINGAPORE_LAYERED = ROOT / "config" / "networks" / "singapore-layered.yaml"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def xvfb_display():
    with private_display() as display:
        yield display


def screenshot(path: Path, out: Path, display: str, tmp: Path) -> np.ndarray:
    from PIL import Image
    render(path, out, display, WINDOW)
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
    right = img[int(0.06 * h):int(0.27 * h), int(0.61 * w):int(0.79 * w)]   # the geographic view
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
