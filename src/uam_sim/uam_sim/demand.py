"""Flight demand: the paper's seeded random request stream and replayable demand files, free of ROS.

Random demand (the paper's setup): every interval (30 s of simulation time) ``rate`` requests are
issued between random distinct aerodromes, each with earliest departure = now and latest departure
= now + ``window_s`` (60 s). The stream is a pure function of (seed, interval index): the random
numbers of interval i come from ``numpy.random.default_rng(SeedSequence([seed, i]))``, so the ROS
request generator node and the in-process experiment runner produce the same requests whatever
order or how often they ask, and one interval can be regenerated alone.

Fractional rates: an interval issues ``floor(rate)`` requests plus one more with probability
``rate - floor(rate)`` (drawn from that interval's RNG). Rate 0.5 gives on average one request
every other interval; the expected count per interval is exactly ``rate``.

Priority and operator mixes (issue 21): with ``priority_share`` p > 0 each request is of class
``priority_class`` with probability p (else class 0), and with ``operators`` each request gets one
of the named operators uniformly; both are drawn from the interval's RNG after the paper's
draws, so without them the stream is exactly the paper's.

Demand files (docs/demand-format.md): a YAML list of requests, each {t_s, origin, destination,
optionally id, window_s or latest_s, priority, operator}, replayed by :class:`DemandSchedule` at the epoch whose
interval contains ``t_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
import yaml

from uam_contract.ids import MAX_NODE_ID_LENGTH, check_id, echo
from uam_planner.objectives import check_priority
from uam_planner.planning import FlightRequest

DEFAULT_INTERVAL_S = 30.0
DEFAULT_WINDOW_S = 60.0


class DemandError(ValueError):
    """Bad demand input; the message names the field and the offending value."""


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or value <= 0:
        raise DemandError(f"{name}: {value!r} must be a positive finite number")
    return float(value)


def request_id(interval_index: int, i: int) -> str:
    """Deterministic id of the i-th request of an interval: ``r{interval:05d}_{i:03d}``."""
    return f"r{int(interval_index):05d}_{int(i):03d}"


class RequestGenerator:
    """The paper's random request stream.

    Args:
        aerodrome_ids: aerodrome node ids (>= 2 distinct) to draw origins and destinations from.
        rate_per_interval: requests per interval (>= 0; fractional allowed, see module doc).
        interval_s: time between generation instants [s] (30 s in the paper).
        window_s: latest departure - earliest departure [s] (60 s in the paper).
        seed: integer >= 0; the stream is a function of (seed, interval index) only.
        priority_share: probability in [0, 1] that a request is of class ``priority_class``
            (e.g. 0.05 medical flights); the others are class 0.
        priority_class: the class of those requests, an integer in [1, 255].
        operators: operator ids a request is drawn from uniformly (empty: no operator_id).
        lead_time_s: requests are filed this long ahead [s] (>= 0): earliest departure
            ``t + lead_time_s``, latest ``t + lead_time_s + window_s`` (for a planning horizon).
        operator_lead_times_s: optional extra lead time [s] per operator (same length as
            ``operators``): filing habits, e.g. (600, 0) for one operator that files 10 min
            ahead and one that files at the last moment.

    ``requests_at(t_s, interval_index)`` returns that interval's requests, requested at ``t_s``,
    earliest departure ``t_s``, latest ``t_s + window_s``. O(rate) per call.
    """

    def __init__(self, aerodrome_ids: Sequence[str], rate_per_interval: float,
                 interval_s: float = DEFAULT_INTERVAL_S, window_s: float = DEFAULT_WINDOW_S,
                 seed: int = 0, priority_share: float = 0.0, priority_class: int = 1,
                 operators: Sequence[str] = (), lead_time_s: float = 0.0,
                 operator_lead_times_s: Sequence[float] = ()):
        ids = [str(a) for a in aerodrome_ids]
        if len(set(ids)) < 2:
            raise DemandError(f"aerodrome_ids: need at least 2 distinct aerodromes, got {ids!r}")
        if len(set(ids)) != len(ids):
            raise DemandError(f"aerodrome_ids: duplicates in {ids!r}")
        r = rate_per_interval
        if isinstance(r, bool) or not isinstance(r, (int, float, np.integer, np.floating)) \
                or not math.isfinite(r) or r < 0:
            raise DemandError(f"rate_per_interval: {r!r} must be a finite number >= 0")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise DemandError(f"seed: {seed!r} must be an integer >= 0")
        self.aerodrome_ids = tuple(ids)
        self.rate_per_interval = float(r)
        self.interval_s = _positive("interval_s", interval_s)
        self.window_s = _positive("window_s", window_s)
        self.seed = int(seed)
        ps = priority_share
        if isinstance(ps, bool) or not isinstance(ps, (int, float, np.integer, np.floating)) \
                or not math.isfinite(ps) or not 0.0 <= ps <= 1.0:
            raise DemandError(f"priority_share: {ps!r} must be a number in [0, 1]")
        if check_priority(priority_class) or priority_class == 0:
            raise DemandError(f"priority_class: {priority_class!r} must be an integer in [1, 255]")
        if isinstance(operators, str):
            raise DemandError(f"operators: {operators!r} must be a list of operator ids, not a string")
        ops = [str(o) for o in operators]
        for o in ops:
            problem = check_id("operators", o)
            if problem:
                raise DemandError(problem)
        if len(set(ops)) != len(ops):
            raise DemandError(f"operators: duplicates in {ops!r}")
        lt = lead_time_s
        if isinstance(lt, bool) or not isinstance(lt, (int, float, np.integer, np.floating)) \
                or not math.isfinite(lt) or lt < 0:
            raise DemandError(f"lead_time_s: {lt!r} must be a finite number >= 0")
        self.lead_time_s = float(lt)
        olt = list(operator_lead_times_s)
        if olt and len(olt) != len(ops):
            raise DemandError(f"operator_lead_times_s: {len(olt)} values for {len(ops)} operators")
        for v in olt:
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or v < 0:
                raise DemandError(f"operator_lead_times_s: {v!r} must be a finite number >= 0")
        self.operator_lead_times_s = tuple(float(v) for v in olt) or (0.0,) * len(ops)
        self.priority_share = float(ps)
        self.priority_class = int(priority_class)
        self.operators = tuple(ops)

    def rng(self, interval_index: int) -> np.random.Generator:
        """The RNG of one interval, derived from (seed, interval_index) only."""
        return np.random.default_rng(np.random.SeedSequence([self.seed, int(interval_index)]))

    def requests_at(self, t_s: float, interval_index: int) -> list[FlightRequest]:
        """The requests issued at ``t_s`` [s] for interval ``interval_index`` (>= 0)."""
        if isinstance(interval_index, bool) or not isinstance(interval_index, (int, np.integer)) \
                or interval_index < 0:
            raise DemandError(f"interval_index: {interval_index!r} must be an integer >= 0")
        if not isinstance(t_s, (int, float, np.integer, np.floating)) or not math.isfinite(t_s):
            raise DemandError(f"t_s: {t_s!r} must be a finite time")
        rng = self.rng(interval_index)
        whole = math.floor(self.rate_per_interval)
        frac = self.rate_per_interval - whole
        extra = rng.random() < frac  # always drawn, so integer rates use the same stream layout
        n = int(whole) + int(extra)
        m = len(self.aerodrome_ids)
        origin = rng.integers(0, m, size=n)
        dest = rng.integers(0, m - 1, size=n)
        dest = dest + (dest >= origin)  # uniform over the aerodromes other than the origin
        # drawn after the paper's numbers, only when asked for: the paper's stream is unchanged
        prio = np.where(rng.random(n) < self.priority_share, self.priority_class, 0) \
            if self.priority_share > 0 else np.zeros(n, dtype=np.int64)
        which = rng.integers(0, len(self.operators), size=n).tolist() if self.operators else []
        ops = [self.operators[j] for j in which] if which else [""] * n
        extra = [self.operator_lead_times_s[j] for j in which] if which else [0.0] * n
        t = float(t_s)
        return [FlightRequest(request_id=request_id(interval_index, i),
                              origin_id=self.aerodrome_ids[o], destination_id=self.aerodrome_ids[d],
                              request_time_s=t, earliest_departure_s=t + self.lead_time_s + extra[i],
                              latest_departure_s=t + self.lead_time_s + extra[i] + self.window_s,
                              priority=int(prio[i]),
                              operator_id=ops[i])
                for i, (o, d) in enumerate(zip(origin.tolist(), dest.tolist()))]

    def requests_for_epoch(self, epoch_index: int) -> list[FlightRequest]:
        """Requests of interval ``epoch_index``, issued at ``epoch_index * interval_s``."""
        return self.requests_at(epoch_index * self.interval_s, epoch_index)


# ---- demand files --------------------------------------------------------------------------------

@dataclass(frozen=True)
class DemandEntry:
    """One request of a demand file (times in simulation seconds)."""

    request_id: str
    t_s: float
    origin: str
    destination: str
    latest_s: float
    priority: int = 0
    operator: str = ""

    def to_request(self) -> FlightRequest:
        return FlightRequest(request_id=self.request_id, origin_id=self.origin,
                             destination_id=self.destination, request_time_s=self.t_s,
                             earliest_departure_s=self.t_s, latest_departure_s=self.latest_s,
                             priority=self.priority, operator_id=self.operator)


_KEYS = {"t_s", "origin", "destination", "window_s", "latest_s", "id", "priority", "operator"}


def parse_demand(data: Any, aerodrome_ids: Iterable[str] | None = None,
                 default_window_s: float = DEFAULT_WINDOW_S, where: str = "demand") -> list[DemandEntry]:
    """Validate a demand list (the parsed YAML) into entries sorted by (t_s, file order).

    Args:
        data: a list of mappings, or a mapping with key ``requests`` holding that list.
        aerodrome_ids: if given, origins and destinations must be among them.
        default_window_s: window [s] for entries giving neither window_s nor latest_s.
        where: prefix for error messages (the file name).
    Raises DemandError naming the entry index, the field and the value. O(n log n).
    """
    if isinstance(data, dict):
        if "requests" not in data:
            raise DemandError(f"{where}: expected a list of requests or a mapping with 'requests', "
                              f"got keys {sorted(data)!r}")
        data = data["requests"]
    if not isinstance(data, list):
        raise DemandError(f"{where}: expected a list of requests, got {type(data).__name__}")
    known = set(aerodrome_ids) if aerodrome_ids is not None else None
    entries, seen = [], set()
    for i, item in enumerate(data):
        at = f"{where}[{i}]"
        if not isinstance(item, dict):
            raise DemandError(f"{at}: expected a mapping, got {item!r}")
        unknown = set(item) - _KEYS
        if unknown:
            raise DemandError(f"{at}: unknown field {sorted(unknown)[0]!r} (known: {sorted(_KEYS)})")
        for key in ("t_s", "origin", "destination"):
            if key not in item:
                raise DemandError(f"{at}.{key}: missing")
        t = item["t_s"]
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or t < 0:
            raise DemandError(f"{at}.t_s: {t!r} must be a finite time >= 0")
        for key in ("origin", "destination"):
            v = item[key]
            if not isinstance(v, (str, int)) or isinstance(v, bool) or str(v) == "" \
                    or len(str(v)) > MAX_NODE_ID_LENGTH:
                raise DemandError(f"{at}.{key}: {echo(v)} must be a node id of 1 to {MAX_NODE_ID_LENGTH} characters")
            if known is not None and str(v) not in known:
                raise DemandError(f"{at}.{key}: {echo(v)} is not an aerodrome of the network")
        if str(item["origin"]) == str(item["destination"]):
            raise DemandError(f"{at}.destination: {item['destination']!r} equals the origin")
        if "window_s" in item and "latest_s" in item:
            raise DemandError(f"{at}.latest_s: give window_s or latest_s, not both")
        if "latest_s" in item:
            lat = item["latest_s"]
            if isinstance(lat, bool) or not isinstance(lat, (int, float)) or not math.isfinite(lat) \
                    or lat < t:
                raise DemandError(f"{at}.latest_s: {lat!r} must be a finite time >= t_s {t!r}")
            latest = float(lat)
        else:
            w = item.get("window_s", default_window_s)
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not math.isfinite(w) or w < 0:
                raise DemandError(f"{at}.window_s: {w!r} must be a finite number >= 0")
            latest = float(t) + float(w)
        rid = item.get("id", f"d{i:05d}")
        if not isinstance(rid, (str, int)) or isinstance(rid, bool):
            raise DemandError(f"{at}.id: {echo(rid)} must be a non-empty string")
        rid = str(rid)
        problem = check_id(f"{at}.id", rid)  # bounded at load as on the wire
        if problem:
            raise DemandError(problem)
        if rid in seen:
            raise DemandError(f"{at}.id: {rid!r} is used by an earlier request")
        seen.add(rid)
        prio = item.get("priority", 0)
        problem = check_priority(prio)
        if problem:
            raise DemandError(f"{at}.{problem}")
        op = item.get("operator", "")
        if op != "":
            problem = check_id(f"{at}.operator", op) if isinstance(op, str) else \
                f"{at}.operator: {echo(op)} must be an operator id"
            if problem:
                raise DemandError(problem)
        entries.append(DemandEntry(rid, float(t), str(item["origin"]), str(item["destination"]),
                                   latest, int(prio), op))
    order = sorted(range(len(entries)), key=lambda j: (entries[j].t_s, j))
    return [entries[j] for j in order]


def load_demand(path, aerodrome_ids: Iterable[str] | None = None,
                default_window_s: float = DEFAULT_WINDOW_S) -> list[DemandEntry]:
    """Read and validate a YAML demand file (format: docs/demand-format.md)."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise DemandError(f"{path}: not valid YAML ({exc})") from None
    return parse_demand(data, aerodrome_ids, default_window_s, where=str(path))


class DemandSchedule:
    """Replays demand-file entries with the same interface as :class:`RequestGenerator`.

    ``requests_at(t_s, interval_index)`` returns the entries with
    ``(interval_index - 1) * interval_s < t_s <= interval_index * interval_s`` (interval 0 takes
    every ``t_s <= 0``), i.e. a request is handed to the planner at the first epoch at or after
    its time; its request time stays as written. O(n) per call.
    """

    def __init__(self, entries: Sequence[DemandEntry], interval_s: float = DEFAULT_INTERVAL_S):
        self.entries = list(entries)
        self.interval_s = _positive("interval_s", interval_s)
        self._t = np.array([e.t_s for e in self.entries], dtype=np.float64)

    def requests_at(self, t_s: float, interval_index: int) -> list[FlightRequest]:
        hi = interval_index * self.interval_s
        lo = (interval_index - 1) * self.interval_s if interval_index > 0 else -math.inf
        idx = np.flatnonzero((self._t > lo) & (self._t <= hi))
        return [self.entries[j].to_request() for j in idx.tolist()]

    def requests_for_epoch(self, epoch_index: int) -> list[FlightRequest]:
        return self.requests_at(epoch_index * self.interval_s, epoch_index)
