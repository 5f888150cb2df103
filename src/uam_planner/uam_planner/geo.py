"""WGS84 geodesy for the routing network: geodetic <-> ECEF <-> local east-north-up (ENU).

Every function is vectorised over leading array dimensions; angles are in degrees, lengths in
metres. The network converts its node coordinates once, at load time, into a local ENU frame about
an origin, and every later computation (corridor lengths, trajectories, separation) works in that
Cartesian frame: over a city-sized area (tens of km) the ENU frame is exact (no projection
distortion; it is a rigid transform of ECEF), only "up" tilts slightly away from the local
vertical far from the origin (about 0.09 degrees at 10 km).
"""

from __future__ import annotations

import numpy as np

#: WGS84 semi-major axis, metres.
WGS84_A_M = 6378137.0
#: WGS84 flattening.
WGS84_F = 1.0 / 298.257223563
#: WGS84 first eccentricity squared.
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def geodetic_to_ecef(lat_deg, lon_deg, alt_m) -> np.ndarray:
    """Geodetic (lat, lon in degrees, alt in metres above the ellipsoid) to ECEF metres.

    Inputs broadcast against each other; returns an array of shape (..., 3). O(n).
    """
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    alt = np.asarray(alt_m, dtype=np.float64)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    n_m = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat**2)  # prime-vertical radius
    x = (n_m + alt) * cos_lat * np.cos(lon)
    y = (n_m + alt) * cos_lat * np.sin(lon)
    z = (n_m * (1.0 - WGS84_E2) + alt) * sin_lat
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def ecef_to_geodetic(ecef_m) -> np.ndarray:
    """ECEF metres (..., 3) to geodetic (..., 3): lat deg, lon deg, alt m above the ellipsoid.

    Fixed-point iteration on the latitude (converges to < 1e-12 rad in a few steps for any point
    near the Earth's surface); the height uses a form that stays accurate near the poles. O(n).
    """
    ecef = np.asarray(ecef_m, dtype=np.float64)
    x, y, z = ecef[..., 0], ecef[..., 1], ecef[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(8):
        sin_lat = np.sin(lat)
        n_m = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
        lat = np.arctan2(z + WGS84_E2 * n_m * sin_lat, p)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    alt = p * cos_lat + z * sin_lat - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    return np.stack([np.degrees(lat), np.degrees(lon), alt], axis=-1)


def _enu_rotation(origin_lat_deg: float, origin_lon_deg: float) -> np.ndarray:
    """Rotation matrix R (3, 3) with enu = R @ (ecef - ecef_origin)."""
    lat, lon = np.radians(origin_lat_deg), np.radians(origin_lon_deg)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    return np.array(
        [
            [-so, co, 0.0],
            [-sl * co, -sl * so, cl],
            [cl * co, cl * so, sl],
        ]
    )


def geodetic_to_enu(lat_lon_alt, origin_lat_lon_alt) -> np.ndarray:
    """Geodetic points (..., 3) [deg, deg, m] to local ENU metres (..., 3) about the origin. O(n)."""
    lla = np.asarray(lat_lon_alt, dtype=np.float64)
    o_lat, o_lon, o_alt = (float(v) for v in origin_lat_lon_alt)
    ecef = geodetic_to_ecef(lla[..., 0], lla[..., 1], lla[..., 2])
    ecef0 = geodetic_to_ecef(o_lat, o_lon, o_alt)
    return (ecef - ecef0) @ _enu_rotation(o_lat, o_lon).T


def enu_to_geodetic(enu_m, origin_lat_lon_alt) -> np.ndarray:
    """Local ENU metres (..., 3) about the origin back to geodetic (..., 3) [deg, deg, m]. O(n)."""
    enu = np.asarray(enu_m, dtype=np.float64)
    o_lat, o_lon, o_alt = (float(v) for v in origin_lat_lon_alt)
    ecef = enu @ _enu_rotation(o_lat, o_lon) + geodetic_to_ecef(o_lat, o_lon, o_alt)
    return ecef_to_geodetic(ecef)


def haversine_m(lat1_deg, lon1_deg, lat2_deg, lon2_deg, radius_m: float = 6371008.8) -> np.ndarray:
    """Great-circle distance in metres on a sphere of mean Earth radius (for quick checks). O(n)."""
    lat1, lon1, lat2, lon2 = (np.radians(np.asarray(v, dtype=np.float64))
                              for v in (lat1_deg, lon1_deg, lat2_deg, lon2_deg))
    h = np.sin((lat2 - lat1) / 2) ** 2 + np.cos(lat1) * np.cos(lat2) * np.sin((lon2 - lon1) / 2) ** 2
    return 2.0 * radius_m * np.arcsin(np.sqrt(np.clip(h, 0.0, 1.0)))
