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

Priority and operator mixes: with ``priority_share`` p > 0 each request is of class
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
from typing import Annotated, Any, Iterable, Optional, Sequence, Union

import numpy as np
import pydantic
import yaml
from pydantic import AfterValidator, Strict

from uam_contract.ids import MAX_NODE_ID_LENGTH, check_id, echo
from uam_contract.validation import parse
from uam_planner.objectives import MAX_PRIORITY, check_priority
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


def _time(value: float) -> float:
    if value < 0:
        raise ValueError("must be a finite time >= 0")
    return value


def _window(value: float) -> float:
    if value < 0:
        raise ValueError("must be a finite number >= 0")
    return value


def _node_id(value):
    if str(value) == "" or len(str(value)) > MAX_NODE_ID_LENGTH:
        raise ValueError(f"must be a node id of 1 to {MAX_NODE_ID_LENGTH} characters")
    return value


def _wire_id(value):
    problem = check_id("id", str(value))  # bounded at load as on the wire
    if problem:
        raise ValueError(problem.split(f"id: {echo(str(value))} ", 1)[-1])
    return value


def _priority(value: int) -> int:
    if check_priority(value):
        raise ValueError(f"is not an integer in [0, {MAX_PRIORITY}]")
    return value


def _operator(value: str) -> str:
    problem = check_id("operator", value) if value != "" else ""
    if problem:
        raise ValueError(problem.split(f"operator: {echo(value)} ", 1)[-1])
    return value


_Time = Annotated[float, Strict()]
_NodeId = Annotated[Union[Annotated[str, Strict()], Annotated[int, Strict()]], AfterValidator(_node_id)]


class _EntryFile(pydantic.BaseModel):
    """One request of a demand file as written (docs/demand-format.md): fields, types, ranges.
    The checks across fields and entries (origin != destination, window_s or latest_s, unique
    ids, the network's aerodromes) follow in :func:`parse_demand`."""

    model_config = pydantic.ConfigDict(extra="forbid", allow_inf_nan=False)
    t_s: Annotated[_Time, AfterValidator(_time)]
    origin: _NodeId
    destination: _NodeId
    window_s: Optional[Annotated[_Time, AfterValidator(_window)]] = None
    latest_s: Optional[_Time] = None
    id: Optional[Annotated[Union[Annotated[str, Strict()], Annotated[int, Strict()]],
                           AfterValidator(_wire_id)]] = None
    # np.integer was accepted (check_priority): lax int, but never True, 1.5 or "1"
    priority: Annotated[Any, AfterValidator(_priority)] = 0
    operator: Annotated[Annotated[str, Strict()], AfterValidator(_operator)] = ""


_KEYS = set(_EntryFile.model_fields)


def parse_demand(data: Any, aerodrome_ids: Iterable[str] | None = None,
                 default_window_s: float = DEFAULT_WINDOW_S, where: str = "demand") -> list[DemandEntry]:
    """Validate a demand list (the parsed YAML) into entries sorted by (t_s, file order).

    Args:
        data: a list of mappings, or a mapping with key ``requests`` holding that list.
        aerodrome_ids: if given, origins and destinations must be among them.
        default_window_s: window [s] for entries giving neither window_s nor latest_s.
        where: prefix for error messages (the file name).
    Raises DemandError naming the entry index, the field and the value (``demand[17].priority:
    300 is not an integer in [0, 255]``). The entries' schema is :class:`_EntryFile` (pydantic,
    one validation of the whole list); O(n log n).
    """
    if isinstance(data, dict):
        if "requests" not in data:
            raise DemandError(f"{where}: expected a list of requests or a mapping with 'requests', "
                              f"got keys {sorted(data)!r}")
        data = data["requests"]
    if not isinstance(data, list):
        raise DemandError(f"{where}: expected a list of requests, got {type(data).__name__}")
    items = parse(list[_EntryFile], data, where=where, error=DemandError)
    known = set(aerodrome_ids) if aerodrome_ids is not None else None
    entries, seen = [], set()
    for i, item in enumerate(items):
        at = f"{where}[{i}]"
        for key in ("origin", "destination"):
            v = getattr(item, key)
            if known is not None and str(v) not in known:
                raise DemandError(f"{at}.{key}: {echo(v)} is not an aerodrome of the network")
        if str(item.origin) == str(item.destination):
            raise DemandError(f"{at}.destination: {item.destination!r} equals the origin")
        if item.window_s is not None and item.latest_s is not None:
            raise DemandError(f"{at}.latest_s: give window_s or latest_s, not both")
        t = data[i]["t_s"]  # as written (the message shows it so)
        if item.latest_s is not None:
            if item.latest_s < item.t_s:
                raise DemandError(f"{at}.latest_s: {data[i]['latest_s']!r} must be a finite time >= t_s {t!r}")
            latest = float(item.latest_s)
        else:
            w = item.window_s if item.window_s is not None else default_window_s
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not math.isfinite(w) or w < 0:
                raise DemandError(f"{at}.window_s: {w!r} must be a finite number >= 0")  # the default
            latest = float(t) + float(w)
        rid = str(item.id) if item.id is not None else f"d{i:05d}"
        if item.id is None:
            problem = check_id(f"{at}.id", rid)
            if problem:
                raise DemandError(problem)
        if rid in seen:
            raise DemandError(f"{at}.id: {rid!r} is used by an earlier request")
        seen.add(rid)
        entries.append(DemandEntry(rid, float(item.t_s), str(item.origin), str(item.destination),
                                   latest, int(item.priority), item.operator))
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
