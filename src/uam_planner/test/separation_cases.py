"""Shared cases of the compiled separation paths' tests (test_any_conflict_compiled.py,
test_conflicting_pairs_compiled.py): long random flights with ties mixed in, and the ties where
a decision could flip on the last bit. Imported from the test folder (pytest's importlib mode
does not let one test file import another)."""

import numpy as np

from uam_planner.separation import SeparationModel
from uam_planner.trajectory import Trajectory

SPHERE = SeparationModel("sphere", 100.0)
CYL = SeparationModel("cylinder", 100.0, 30.0)
LEVELS = [60.0, 90.0, 120.0, 150.0]


def long_flight(rng, t0, n_legs):
    """A flight of ``n_legs`` legs at 8-15 m/s between random points, levels changing between
    legs (climbs and descents): with 4-8 legs it lasts longer than the deciding stages."""
    pts = [np.array([*rng.uniform(-2000, 2000, 2), rng.choice(LEVELS)])]
    times = [t0]
    for _ in range(n_legs):
        p = np.array([*rng.uniform(-2000, 2000, 2), rng.choice(LEVELS)])
        times.append(times[-1] + np.linalg.norm(p - pts[-1]) / rng.uniform(8.0, 15.0) + 1.0)
        pts.append(p)
    return Trajectory(np.array(times), np.array(pts))


def random_case(seed, n_a, n_b):
    """Random long flights a and b, and ties: some of b fly a's path the separation ahead or
    behind in time (10 s at 10 m/s for a straight copy), one level (V) up, or one rounding step
    off a level."""
    rng = np.random.default_rng(seed)
    a = [long_flight(rng, rng.uniform(0, 60), int(rng.integers(1, 8))) for _ in range(n_a)]
    b = [long_flight(rng, rng.uniform(-600, 900), int(rng.integers(1, 8))) for _ in range(n_b)]
    for k in range(0, n_a, 4):
        tr = a[k]
        pts = tr.points_m.copy()
        if k % 8 == 4:
            pts[:, 2] = pts[:, 2] + 30.0
        if k % 12 == 0:
            pts[1:, 2] = np.nextafter(pts[1:, 2], np.inf if k % 24 else -np.inf)
        b.append(Trajectory(tr.times_s + rng.choice([-10.0, 10.0, 0.0, 600.0]), pts))
    return a, b


def line(t0, t1, p0, p1):
    return Trajectory(np.array([t0, t1], float), np.array([p0, p1], float))


def ties():
    """(name, a, b, loses in the cylinder, loses in the sphere): one flight against one."""
    east = line(0, 200, (-1000, 0, 90), (1000, 0, 90))
    up = 90.0 + 30.0
    below = np.nextafter(up, 0.0)
    north = line(0, 100, (0, -500, 90), (0, 500, 90))
    return [
        ("V above", east, line(0, 200, (-1000, 0, up), (1000, 0, up)), False, True),
        ("a step less than V above", east, line(0, 200, (-1000, 0, below), (1000, 0, below)),
         True, True),
        ("touching in time", north, line(100, 150, (0, 500, 90), (0, 1000, 90)), True, True),
        ("a step apart in time", north,
         line(np.nextafter(100.0, np.inf), 150, (0, 500, 90), (0, 1000, 90)), False, False),
        ("same velocity, the separation ahead", east,
         line(0, 200, (-900, 0, 90), (1100, 0, 90)), False, False),
        ("same velocity, a step closer", east,
         line(0, 200, (np.nextafter(-900.0, -np.inf), 0, 90), (np.nextafter(1100.0, -np.inf), 0,
                                                                 90)), True, True),
        ("same velocity, the separation above", east,
         line(0, 200, (-1000, 0, 190), (1000, 0, 190)), False, False),
    ]
