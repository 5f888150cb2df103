#!/usr/bin/env python3
"""Build config/networks/singapore.yaml (+ singapore.graphml): our own UAM corridor network over
Singapore's real geography.

Usage (from the repository root):
    .venv/bin/python scripts/build_singapore_network.py [--plot results/singapore_network.png]

It also writes config/networks/singapore-layered.yaml: the same nodes and corridors as a layered
network (docs/network-format.md): vertiports as route terminals with LAYERED_PADS_M pads each,
cruise levels LAYERED_LEVELS_M and the semicircular direction rule.

How the network is made (all data is in this file):
- AERODROMES: vertiports at town centres, business districts and hospitals. Coordinates are
  public: MRT station coordinates from OneMap (Singapore Land Authority) as mirrored in public
  data sets, and OpenStreetMap / Wikipedia coordinates for the hospitals; rounded to 4 decimals
  (about 11 m). Aerodromes are at ground level plus a landing-pad height (AERODROME_ALT_M).
- NO_FLY_ZONES: circles around Changi Airport, Paya Lebar Air Base, Seletar Airport and Tengah
  Air Base, centred on the aerodrome reference points given by Wikipedia (from the AIP).
- ROUTES: polylines of (lat, lon) way points traced by hand along expressways (PIE, AYE, CTE,
  BKE, KJE, SLE, TPE, ECP, KPE, MCE), rivers and canals (Singapore River, Alexandra Canal, Kallang
  River, Bukit Timah/Rochor Canal, Sungei Punggol) and the coast, after OpenStreetMap; they are
  approximate (a few hundred metres). Named junctions are shared by the routes that meet there.
- Processing: way points inside a zone (plus ZONE_MARGIN_M) are pushed radially out to its edge,
  so corridors skirt the zones; each leg between junctions is resampled every ~1 km (0.67-1.5 km);
  where two corridors cross in plan, a junction node is inserted; each aerodrome is joined to its
  2 nearest corridor nodes (within ACCESS_MAX_M, not crossing a zone). Corridor nodes fly at
  CRUISE_ALT_M. The result is validated by uam_planner.network (no node in, no corridor through,
  a zone; all aerodromes mutually reachable) and written as YAML and GraphML.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src" / "uam_planner"))

from uam_planner.geo import enu_to_geodetic, geodetic_to_enu  # noqa: E402
from uam_planner.network import (  # noqa: E402
    build_network, load_network, save_network_graphml, save_network_yaml)

ORIGIN = (1.3521, 103.8198, 0.0)  # commonly cited centre of Singapore (Wikipedia)
CRUISE_ALT_M = 120.0              # corridor altitude above the reference surface
AERODROME_ALT_M = 5.0             # landing pad: ground level plus a few metres
TARGET_SPACING_M = 1000.0         # corridor node spacing target along a route
MIN_SPACING_M = 350.0             # shorter corridors next to a crossing are merged away
ZONE_MARGIN_M = 150.0             # way points are pushed this far outside a zone's radius
ACCESS_LINKS = 2                  # corridor nodes each aerodrome is joined to
ACCESS_MAX_M = 2500.0             # longest aerodrome access link (horizontal)
# Layered variant: four cruise levels 30 m apart (the cylinder's V), eastbound tracks on 60 and
# 120 m, westbound on 90 and 150 m; four pads per vertiport on a 150 m square (level index i
# uses pad i), so flights leaving for different levels climb more than H = 100 m apart.
LAYERED_LEVELS_M = [60.0, 90.0, 120.0, 150.0]
LAYERED_PADS_M = [[-75.0, -75.0], [75.0, -75.0], [75.0, 75.0], [-75.0, 75.0]]

# name, lat, lon, radius_m. Reference points: Wikipedia (from the AIP). Radius: Changi 5 km (the
# CAAS 5 km rule around aerodromes); the air bases 3 km, which covers each runway with at least
# 1 km to spare (Paya Lebar's 3.8 km runway, Seletar's 1.8 km, Tengah's 2.7 km). A 5 km disc at
# Paya Lebar would cut off Hougang, Sengkang, Tampines and Bedok altogether.
NO_FLY_ZONES = [
    ("Changi Airport", 1.3592, 103.9894, 5000.0),
    ("Paya Lebar Air Base", 1.3604, 103.9097, 3000.0),
    ("Seletar Airport", 1.4169, 103.8678, 3000.0),
    ("Tengah Air Base", 1.3872, 103.7086, 3000.0),
]

# id suffix, human name, lat, lon
AERODROMES = [
    ("JURONG_EAST", "Jurong East", 1.3332, 103.7423),
    ("BOON_LAY", "Boon Lay (Jurong West)", 1.3386, 103.7061),
    ("JOO_KOON", "Joo Koon (Jurong industrial)", 1.3277, 103.6784),
    ("TUAS", "Tuas Link", 1.3409, 103.6370),
    ("CLEMENTI", "Clementi", 1.3151, 103.7652),
    ("ONE_NORTH", "one-north", 1.2998, 103.7875),
    ("NUH", "National University Hospital", 1.2937, 103.7831),
    ("HARBOURFRONT", "HarbourFront", 1.2654, 103.8215),
    ("SGH", "Singapore General Hospital", 1.2795, 103.8348),
    ("MARINA_BAY", "Marina Bay", 1.2763, 103.8554),
    ("ORCHARD", "Orchard (Somerset)", 1.3003, 103.8391),
    ("TTSH", "Tan Tock Seng Hospital", 1.3215, 103.8458),
    ("TOA_PAYOH", "Toa Payoh", 1.3326, 103.8475),
    ("BISHAN", "Bishan", 1.3513, 103.8491),
    ("ANG_MO_KIO", "Ang Mo Kio", 1.3699, 103.8496),
    ("SERANGOON", "Serangoon", 1.3506, 103.8728),
    ("KALLANG", "Kallang (Stadium)", 1.3028, 103.8753),
    ("PAYA_LEBAR", "Paya Lebar Central", 1.3172, 103.8923),
    ("BEDOK", "Bedok", 1.3240, 103.9300),
    ("TAMPINES", "Tampines (Tampines West)", 1.3455, 103.9384),
    ("SENGKANG", "Sengkang", 1.3917, 103.8955),
    ("PUNGGOL", "Punggol", 1.4052, 103.9024),
    ("YISHUN", "Yishun", 1.4294, 103.8350),
    ("WOODLANDS", "Woodlands", 1.4361, 103.7879),
    ("CHOA_CHU_KANG", "Choa Chu Kang", 1.3854, 103.7444),
    ("BUKIT_PANJANG", "Bukit Panjang", 1.3790, 103.7615),
]

# Junctions shared between routes: name -> (lat, lon, human name)
JUNCTIONS = {
    "TUAS_CHECKPOINT": (1.3480, 103.6360, "AYE at Tuas Checkpoint"),
    "TUAS": (1.3420, 103.6460, "AYE / PIE at Tuas"),
    "AYE_JURONG": (1.3230, 103.7380, "AYE / Jurong Town Hall Road"),
    "AYE_CLEMENTI": (1.3110, 103.7650, "AYE / Clementi Road"),
    "AYE_NUH": (1.2960, 103.7850, "AYE / North Buona Vista Road"),
    "AYE_QUEENSWAY": (1.2880, 103.8040, "AYE / Queensway"),
    "AYE_CTE": (1.2755, 103.8300, "AYE / CTE"),
    "KEPPEL": (1.2740, 103.8360, "AYE at Keppel"),
    "MCE_W": (1.2730, 103.8450, "AYE / MCE"),
    "MCE_MID": (1.2740, 103.8640, "MCE at Marina South"),
    "MCE_E": (1.2900, 103.8760, "MCE / ECP"),
    "HARBOURFRONT": (1.2620, 103.8180, "Coast at HarbourFront"),
    "PIE_JURONG_WEST": (1.3440, 103.6980, "PIE at Jurong West"),
    "PIE_KJE": (1.3480, 103.7180, "PIE / KJE"),
    "PIE_JURONG_EAST": (1.3400, 103.7450, "PIE / Jurong Town Hall Road"),
    "PIE_BKE": (1.3390, 103.7700, "PIE / BKE"),
    "PIE_BUKIT_TIMAH": (1.3370, 103.7820, "PIE / Bukit Timah Road"),
    "PIE_HOLLAND": (1.3340, 103.7950, "PIE / Holland Road"),
    "PIE_THOMSON": (1.3260, 103.8350, "PIE / Thomson Road"),
    "PIE_CTE": (1.3280, 103.8520, "PIE / CTE"),
    "PIE_KALLANG": (1.3270, 103.8610, "PIE / Kallang River"),
    "PIE_KPE": (1.3320, 103.8830, "PIE / KPE"),
    "PIE_TAMPINES": (1.3400, 103.9330, "PIE at Tampines"),
    "CTE_RIVER": (1.2920, 103.8420, "CTE / Singapore River"),
    "CTE_SLE_TPE": (1.3900, 103.8660, "CTE / SLE / TPE"),
    "BKE_KJE": (1.3800, 103.7680, "BKE / KJE"),
    "KJE_CCK": (1.3750, 103.7430, "KJE / Choa Chu Kang Road"),
    "BKE_SLE": (1.4150, 103.7740, "BKE / SLE"),
    "WOODLANDS_C": (1.4330, 103.7720, "BKE at Woodlands"),
    "WOODLANDS_CP": (1.4440, 103.7690, "Woodlands Checkpoint"),
    "SLE_THOMSON": (1.4050, 103.8180, "SLE / Upper Thomson Road"),
    "SLE_YISHUN": (1.4000, 103.8400, "SLE / Yishun Avenue 2"),
    "BISHAN_PARK": (1.3620, 103.8420, "Bishan-Ang Mo Kio Park"),
    "YISHUN": (1.4330, 103.8370, "Yishun"),
    "TPE_SENGKANG": (1.3870, 103.8930, "TPE at Sengkang"),
    "TPE_KPE": (1.3830, 103.9060, "TPE / KPE"),
    "TPE_PUNGGOL": (1.3800, 103.9190, "TPE / Punggol Road"),
    "TPE_TAMPINES": (1.3700, 103.9400, "TPE at Tampines"),
    "PUNGGOL": (1.4050, 103.9040, "Punggol"),
    "ECP_KALLANG": (1.2990, 103.8800, "ECP / KPE"),
    "ECP_BEDOK": (1.3130, 103.9340, "ECP at Bedok"),
    "ECP_EAST": (1.3190, 103.9480, "ECP at East Coast Park (east end)"),
    "KALLANG_BASIN": (1.3020, 103.8700, "Kallang Basin"),
    "MARINA_BAY": (1.2860, 103.8560, "Marina Bay"),
    "ROCHOR": (1.3040, 103.8560, "Rochor Canal"),
    "ALEXANDRA": (1.2935, 103.8330, "Singapore River / Alexandra Canal"),
    "ADMIRALTY_COAST": (1.4530, 103.8080, "North coast at Admiralty"),
}

# route label -> list of way points: a junction name or (lat, lon). Each route starts and ends
# at a junction.
ROUTES = {
    "AYE": ["TUAS_CHECKPOINT", "TUAS", (1.3300, 103.6560), (1.3200, 103.6720), (1.3150, 103.6900),
            (1.3170, 103.7080), (1.3200, 103.7230), "AYE_JURONG", (1.3180, 103.7540),
            "AYE_CLEMENTI", (1.3030, 103.7760), "AYE_NUH", (1.2910, 103.7960), "AYE_QUEENSWAY",
            (1.2830, 103.8140), "AYE_CTE", "KEPPEL", "MCE_W"],
    "MCE": ["MCE_W", (1.2705, 103.8540), "MCE_MID", (1.2800, 103.8700), "MCE_E"],
    "ECP": ["MCE_E", "ECP_KALLANG", (1.3010, 103.8920), (1.3020, 103.9050), (1.3060, 103.9180),
            "ECP_BEDOK", "ECP_EAST"],
    "PIE": ["TUAS", (1.3420, 103.6620), (1.3430, 103.6800), "PIE_JURONG_WEST", (1.3460, 103.7090),
            "PIE_KJE", (1.3440, 103.7300), "PIE_JURONG_EAST", (1.3380, 103.7560), "PIE_BKE",
            "PIE_BUKIT_TIMAH", "PIE_HOLLAND", (1.3310, 103.8080), (1.3270, 103.8200),
            "PIE_THOMSON", "PIE_CTE", "PIE_KALLANG", (1.3290, 103.8720), "PIE_KPE",
            (1.3325, 103.8950), (1.3330, 103.9080), (1.3345, 103.9200), "PIE_TAMPINES"],
    "CTE": ["AYE_CTE", (1.2850, 103.8400), "CTE_RIVER", (1.3010, 103.8430), (1.3100, 103.8470),
            (1.3190, 103.8500), "PIE_CTE", (1.3380, 103.8570), (1.3480, 103.8600),
            (1.3580, 103.8620), (1.3680, 103.8630), (1.3790, 103.8650), "CTE_SLE_TPE"],
    "BKE": ["PIE_BKE", (1.3500, 103.7710), (1.3620, 103.7700), "BKE_KJE", (1.3930, 103.7700),
            "BKE_SLE", "WOODLANDS_C", "WOODLANDS_CP"],
    "KJE": ["PIE_KJE", (1.3580, 103.7260), (1.3680, 103.7350), "KJE_CCK", (1.3790, 103.7560),
            "BKE_KJE"],
    "SLE": ["BKE_SLE", (1.4130, 103.7900), (1.4090, 103.8050), "SLE_THOMSON", (1.4020, 103.8300),
            "SLE_YISHUN", (1.3960, 103.8530), "CTE_SLE_TPE"],
    "TPE": ["CTE_SLE_TPE", (1.3880, 103.8790), "TPE_SENGKANG", "TPE_KPE", "TPE_PUNGGOL",
            (1.3760, 103.9310), "TPE_TAMPINES"],
    "KPE": ["ECP_KALLANG", (1.3080, 103.8790), (1.3190, 103.8810), "PIE_KPE", (1.3440, 103.8860),
            (1.3560, 103.8880), (1.3700, 103.8930), "TPE_KPE"],
    "Woodlands Road": ["PIE_JURONG_EAST", (1.3490, 103.7496), (1.3590, 103.7520), "KJE_CCK",
                       (1.3860, 103.7440), (1.3975, 103.7474), (1.4110, 103.7540),
                       (1.4251, 103.7621), "WOODLANDS_C"],
    "Jurong Town Hall Road": ["AYE_JURONG", "PIE_JURONG_EAST"],
    "Clementi Road": ["AYE_CLEMENTI", (1.3250, 103.7680), "PIE_BKE"],
    "North Buona Vista Road": ["AYE_NUH", (1.3070, 103.7900), (1.3200, 103.7950), "PIE_HOLLAND"],
    "West Coast": ["AYE_CLEMENTI", (1.3000, 103.7640), (1.2900, 103.7700), (1.2810, 103.7820),
                   (1.2740, 103.7950), (1.2680, 103.8080), "HARBOURFRONT", "KEPPEL"],
    "Singapore River": ["MARINA_BAY", (1.2868, 103.8505), (1.2890, 103.8460), "CTE_RIVER",
                        "ALEXANDRA"],
    "Alexandra Canal": ["ALEXANDRA", (1.2920, 103.8250), (1.2905, 103.8170),
                        "AYE_QUEENSWAY"],
    "Marina Bay waterfront": ["MCE_MID", "MARINA_BAY", (1.2950, 103.8620), "KALLANG_BASIN"],
    "Kallang Basin": ["KALLANG_BASIN", "ECP_KALLANG"],
    "Kallang River": ["KALLANG_BASIN", (1.3110, 103.8650), (1.3200, 103.8620), "PIE_KALLANG",
                      (1.3380, 103.8530), (1.3480, 103.8460), "BISHAN_PARK"],
    "Bukit Timah Canal": ["KALLANG_BASIN", "ROCHOR", (1.3100, 103.8430), (1.3170, 103.8290),
                          (1.3240, 103.8140), (1.3300, 103.8020), "PIE_BUKIT_TIMAH"],
    "Thomson Road": ["PIE_THOMSON", (1.3370, 103.8400), (1.3544, 103.8329), (1.3650, 103.8310),
                     (1.3800, 103.8280), (1.3950, 103.8190), "SLE_THOMSON"],
    "Ang Mo Kio - Yishun": ["BISHAN_PARK", (1.3740, 103.8460), (1.3850, 103.8430), "SLE_YISHUN",
                            (1.4120, 103.8340), (1.4230, 103.8340), "YISHUN"],
    "North coast": ["WOODLANDS_CP", (1.4520, 103.7800), (1.4540, 103.7950), "ADMIRALTY_COAST",
                    (1.4560, 103.8200), (1.4480, 103.8300), "YISHUN"],
    "Woodlands Avenue": ["WOODLANDS_C", (1.4340, 103.7840), (1.4380, 103.7960),
                         "ADMIRALTY_COAST"],
    "Sungei Punggol": ["TPE_SENGKANG", (1.3960, 103.8990), "PUNGGOL"],
    "Punggol Road": ["PUNGGOL", (1.3950, 103.9160), "TPE_PUNGGOL"],
    "Tampines Avenue": ["TPE_TAMPINES", (1.3580, 103.9400), (1.3480, 103.9370), "PIE_TAMPINES"],
    "Sungei Bedok": ["PIE_TAMPINES", (1.3300, 103.9320), "ECP_BEDOK"],
}


def _xy(lat: float, lon: float) -> np.ndarray:
    return geodetic_to_enu([lat, lon, 0.0], ORIGIN)[:2]


def _zone_xy() -> list[tuple[str, np.ndarray, float]]:
    return [(name, _xy(lat, lon), r) for name, lat, lon, r in NO_FLY_ZONES]


def push_out(p: np.ndarray, zones) -> np.ndarray:
    """Move a point radially out of every zone it is inside (radius + ZONE_MARGIN_M)."""
    p = np.array(p, dtype=float)
    for _ in range(3):  # zones do not overlap; a second pass only confirms
        for _, c, r in zones:
            d = np.linalg.norm(p - c)
            if d < r + ZONE_MARGIN_M:
                p = c + (p - c) / max(d, 1e-9) * (r + ZONE_MARGIN_M)
    return p


def seg_dist(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    d = b - a
    t = np.clip(np.dot(c - a, d) / max(np.dot(d, d), 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(a + t * d - c))


def resample(points: list[np.ndarray]) -> list[np.ndarray]:
    """Points along a polyline leg every ~TARGET_SPACING_M (end points kept, interior resampled)."""
    pts = np.array(points)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    total = cum[-1]
    n = max(1, int(round(total / TARGET_SPACING_M)))
    s = np.linspace(0.0, total, n + 1)
    x = np.interp(s, cum, pts[:, 0])
    y = np.interp(s, cum, pts[:, 1])
    return [np.array([xi, yi]) for xi, yi in zip(x, y)]


def _intersect(p, p2, q, q2):
    """Proper crossing parameters (t, u) of segments p-p2 and q-q2, or None."""
    r, s = p2 - p, q2 - q
    den = r[0] * s[1] - r[1] * s[0]
    if abs(den) < 1e-9:
        return None
    qp = q - p
    t = (qp[0] * s[1] - qp[1] * s[0]) / den
    u = (qp[0] * r[1] - qp[1] * r[0]) / den
    eps = 1e-6
    if eps < t < 1 - eps and eps < u < 1 - eps:
        return t, u
    return None


def build():
    zones = _zone_xy()
    node_xy: dict[str, np.ndarray] = {}
    node_name: dict[str, str] = {}
    for key, (lat, lon, label) in JUNCTIONS.items():
        node_xy[f"J_{key}"] = push_out(_xy(lat, lon), zones)
        node_name[f"J_{key}"] = label

    segments: list[tuple[str, str, str]] = []  # (u, v, route)
    for route, way in ROUTES.items():
        tag = route.upper().replace(" - ", "_").replace(" ", "_").replace("-", "_")
        # split into legs at junctions
        if not (isinstance(way[0], str) and isinstance(way[-1], str)):
            raise SystemExit(f"route {route!r} must start and end at a junction")
        legs, leg = [], []
        for w in way:
            if isinstance(w, str):
                leg.append((f"J_{w}", node_xy[f"J_{w}"]))
                if len(leg) > 1:
                    legs.append(leg)
                leg = [leg[-1]]
            else:
                leg.append((None, push_out(_xy(*w), zones)))
        k = 0
        for leg in legs:
            pts = resample([p for _, p in leg])
            ids = [leg[0][0]]
            for p in pts[1:-1]:
                k += 1
                nid = f"{tag}_{k:02d}"
                node_xy[nid] = push_out(p, zones)
                node_name[nid] = route
                ids.append(nid)
            ids.append(leg[-1][0])
            segments += [(a, b, route) for a, b in zip(ids[:-1], ids[1:])]

    # Keep corridors out of the zones: split a segment whose chord dips into a zone.
    changed = True
    while changed:
        changed = False
        out = []
        for a, b, r in segments:
            pa, pb = node_xy[a], node_xy[b]
            if any(seg_dist(pa, pb, c) < rad + 20.0 for _, c, rad in zones):
                mid = f"{a}_{b}_m"
                node_xy[mid] = push_out((pa + pb) / 2, zones)
                node_name[mid] = r
                out += [(a, mid, r), (mid, b, r)]
                changed = True
            else:
                out.append((a, b, r))
        segments = out

    # Insert a junction where two corridors cross in plan.
    splits: dict[int, list[tuple[float, str]]] = {}
    n_cross = 0
    for i in range(len(segments)):
        a, b, r1 = segments[i]
        for j in range(i + 1, len(segments)):
            c, d, r2 = segments[j]
            if len({a, b, c, d}) < 4:
                continue
            hit = _intersect(node_xy[a], node_xy[b], node_xy[c], node_xy[d])
            if hit is None:
                continue
            n_cross += 1
            xid = f"X_{n_cross:02d}"
            node_xy[xid] = node_xy[a] + hit[0] * (node_xy[b] - node_xy[a])
            node_name[xid] = f"{r1} x {r2}"
            splits.setdefault(i, []).append((hit[0], xid))
            splits.setdefault(j, []).append((hit[1], xid))
    final = []
    for i, (a, b, r) in enumerate(segments):
        chain = [a] + [x for _, x in sorted(splits.get(i, []))] + [b]
        final += [(u, v, r) for u, v in zip(chain[:-1], chain[1:])]
    segments = final

    # A crossing often lands a few hundred metres from a route node: merge such a plain route
    # node into its neighbour junction so no corridor is much shorter than the target spacing.
    def plain(nid: str) -> bool:
        return not nid.startswith(("J_", "X_")) and not nid.endswith("_m")

    while True:
        short = [(a, b) for a, b, _ in segments
                 if np.linalg.norm(node_xy[a] - node_xy[b]) < MIN_SPACING_M
                 and (plain(a) or plain(b))]
        if not short:
            break
        a, b = short[0]
        drop, keep = (a, b) if plain(a) else (b, a)
        segments = [(keep if u == drop else u, keep if v == drop else v, r)
                    for u, v, r in segments]
        segments = [(u, v, r) for u, v, r in segments if u != v]
        del node_xy[drop]

    # Deduplicate (two routes sharing a junction pair).
    seen, corridors = set(), []
    for a, b, r in segments:
        key = tuple(sorted((a, b)))
        if a != b and key not in seen:
            seen.add(key)
            corridors.append((a, b, r))

    corridor_ids = list(node_xy)
    cxy = np.array([node_xy[n] for n in corridor_ids])
    nodes = []
    for nid in corridor_ids:
        lat, lon, _ = enu_to_geodetic([*node_xy[nid], 0.0], ORIGIN)
        nodes.append({"id": nid, "lat": round(float(lat), 6), "lon": round(float(lon), 6),
                      "alt_m": CRUISE_ALT_M, "aerodrome": False, "name": node_name[nid]})
    # Aerodromes and their access links.
    for key, label, lat, lon in AERODROMES:
        aid = f"AD_{key}"
        p = _xy(lat, lon)
        nodes.insert(len([n for n in nodes if n["aerodrome"]]),
                     {"id": aid, "lat": lat, "lon": lon, "alt_m": AERODROME_ALT_M,
                      "aerodrome": True, "name": label})
        dist = np.linalg.norm(cxy - p, axis=1)
        linked = 0
        for idx in np.argsort(dist):
            if dist[idx] > ACCESS_MAX_M or linked == ACCESS_LINKS:
                break
            if any(seg_dist(p, cxy[idx], c) < rad for _, c, rad in zones):
                continue
            corridors.append((aid, corridor_ids[idx], "access"))
            linked += 1
        if linked == 0:
            raise SystemExit(f"aerodrome {aid} has no corridor node within {ACCESS_MAX_M} m")
    zones_yaml = [{"name": n, "lat": la, "lon": lo, "radius_m": r} for n, la, lo, r in NO_FLY_ZONES]
    net = build_network("singapore", nodes, [{"from": a, "to": b} for a, b, _ in corridors],
                        origin={"lat": ORIGIN[0], "lon": ORIGIN[1], "alt_m": ORIGIN[2]},
                        no_fly_zones=zones_yaml)
    route_of = {tuple(sorted((a, b))): r for a, b, r in corridors}
    routes = [route_of[tuple(sorted((net.node_ids[u], net.node_ids[v])))]
              for u, v in net.edges.tolist()]
    return net, routes, n_cross


HEADER = """\
Singapore UAM corridor network (our own; the paper's came from a proprietary simulator).
Generated by scripts/build_singapore_network.py -- edit that script, not this file.
Schema: docs/network-format.md. Altitudes in metres above the reference surface (WGS84).
Sources: aerodrome coordinates are public MRT station coordinates (OneMap, Singapore Land
Authority) used as town-centre points, and OpenStreetMap / Wikipedia coordinates for hospitals;
no-fly zone centres are the aerodrome reference points on Wikipedia (from the AIP); corridor way
points were traced by hand along expressways, rivers, canals and the coast after OpenStreetMap
(approximate, a few hundred metres).
Aerodromes (AD_*) are at ground level + {aero:g} m; corridor nodes fly at {cruise:g} m. Junctions
J_* join routes; X_* mark where two corridors cross; other ids are <ROUTE>_<k> along a route.
No-fly zones: Changi 5 km; Paya Lebar, Seletar and Tengah 3 km (see the script for why).
Stats: {n} nodes ({a} aerodromes), {m} corridors, corridor length {lmin:.0f}-{lmax:.0f} m
(median {lmed:.0f} m, access links included)."""


LAYERED_HEADER = """
Layered variant (singapore-layered.yaml): the same nodes and corridors; vertiports are route
terminals (no route passes through one it does not use); four pads per vertiport on a 150 m
square; cruise levels 60/90/120/150 m with the semicircular rule (tracks 0-180 deg on 60/120 m,
180-360 deg on 90/150 m). Corridor node altitudes are kept but unused: flights cruise at levels."""


def layered_network(net):
    """The layered variant of ``net``: same nodes and corridors, levels and pads added."""
    from uam_planner.network import network_to_dict, network_from_dict
    d = network_to_dict(net)
    d["name"] = net.name + "-layered"
    d["airspace"] = {"levels_m": LAYERED_LEVELS_M, "direction_rule": "semicircular"}
    for node in d["nodes"]:
        if node["aerodrome"]:
            node["pads_m"] = [list(p) for p in LAYERED_PADS_M]
    return network_from_dict(d)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", default=str(ROOT / "config" / "networks"))
    ap.add_argument("--plot", default=None, help="write a PNG of the network here")
    args = ap.parse_args(argv)
    net, routes, n_cross = build()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    corr = np.array([r != "access" for r in routes])
    lengths = net.edge_length_m
    header = HEADER.format(aero=AERODROME_ALT_M, cruise=CRUISE_ALT_M, n=net.n_nodes,
                           a=len(net.aerodrome_ids), m=net.n_edges, lmin=lengths.min(),
                           lmax=lengths.max(), lmed=float(np.median(lengths)))
    save_network_yaml(net, out / "singapore.yaml", header=header, corridor_routes=routes,
                      extra={"description": "UAM corridors along Singapore expressways, rivers "
                                            "and coast; 26 aerodromes",
                             "cruise_alt_m": CRUISE_ALT_M})
    save_network_graphml(net, out / "singapore.graphml")
    again = load_network(out / "singapore.yaml")
    assert np.allclose(again.enu_m, net.enu_m) and np.array_equal(again.edges, net.edges)
    layered = layered_network(net)
    save_network_yaml(layered, out / "singapore-layered.yaml", header=header + LAYERED_HEADER,
                      corridor_routes=routes,
                      extra={"description": "Singapore corridors as a layered network: "
                                            "vertiports with 4 pads, levels 60/90/120/150 m, "
                                            "semicircular rule"})
    again = load_network(out / "singapore-layered.yaml")
    assert again.levels_m == layered.levels_m and again.pads_m == layered.pads_m
    print(f"{layered}: {len(layered.pads_m)} vertiports with {len(LAYERED_PADS_M)} pads")
    print(f"{net}: {n_cross} crossings made junctions; corridor lengths (no access links) "
          f"min {lengths[corr].min():.0f} m, median {np.median(lengths[corr]):.0f} m, "
          f"max {lengths[corr].max():.0f} m, mean {lengths[corr].mean():.0f} m")
    short = np.flatnonzero(corr & (lengths < 300))
    print(f"{len(short)} corridors shorter than 300 m")
    if args.plot:
        plot(net, routes, args.plot)
        print(f"plot: {args.plot}")
    return 0


def plot(net, routes, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(16, 10))
    lat, lon = net.lat_lon_alt[:, 0], net.lat_lon_alt[:, 1]
    for (u, v), r in zip(net.edges.tolist(), routes):
        ax.plot([lon[u], lon[v]], [lat[u], lat[v]], "-",
                color="0.6" if r == "access" else "tab:blue", lw=0.8 if r == "access" else 1.4)
    c = ~net.is_aerodrome
    ax.plot(lon[c], lat[c], ".", color="tab:blue", ms=3)
    ax.plot(lon[~c], lat[~c], "^", color="tab:red", ms=7)
    for i in np.flatnonzero(net.is_aerodrome):
        ax.annotate(net.names[i], (lon[i], lat[i]), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    for z in net.no_fly_zones:
        t = np.linspace(0, 2 * np.pi, 200)
        r_lat = z.radius_m / 110574.0
        r_lon = z.radius_m / (111320.0 * math.cos(math.radians(z.lat)))
        ax.plot(z.lon + r_lon * np.cos(t), z.lat + r_lat * np.sin(t), "k--", lw=1)
        ax.text(z.lon, z.lat, z.name, ha="center", fontsize=8)
    ax.set_aspect(1.0 / math.cos(math.radians(1.35)))
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_title(f"{net}")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())
