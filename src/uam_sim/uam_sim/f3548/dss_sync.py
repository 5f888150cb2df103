"""The DSS's operational intent references kept in step with the intents this USS serves
(docs/f3548.md, "DSS reference management"). No ROS.

:class:`DssSync` compares what an :class:`~uam_sim.f3548.uss_server.IntentStore` serves
(:meth:`~uam_sim.f3548.uss_server.IntentStore.views`: each live intent's local version, state and
volumes) with the references it has put in the DSS (a :class:`~uam_sim.f3548.dss.DssClient`), and
for each difference:

- a new intent (Accepted, Activated or Contingent): its extents (:func:`extents_of`), the key (the
  OVNs of every operational intent and constraint reference the DSS finds in their bounding
  volume; a peer's OVN, which the DSS shows only to its manager, read from that peer's details
  endpoint), then the reference created; a 409 ``AirspaceConflictResponse``: the missing
  references' OVNs added to the key, and the put made once more;
- a new version (a new plan version, or a state change such as Accepted to Activated): the same,
  as an update at the OVN the DSS gave last, on the same subscription;
- an intent no longer served (ended, cancelled, pruned, a new run): the reference deleted.

After each change the DSS's reference becomes the one served for that version
(:meth:`~uam_sim.f3548.uss_server.IntentStore.set_reference`: its version, OVN, manager and
subscription) and every subscriber the DSS's answer names, other than this USS, is notified:
``POST {uss_base_url}/uss/v1/operational_intents`` with ``PutOperationalIntentDetailsParameters``
(the intent's reference and details, none for a deletion, and that USS's subscriptions with their
notification indices), with a bearer token for that USS from the token source.

Failures (no answer from the DSS, a 409 after the retry, an error answer, a peer that does not
answer) are logged and counted in :attr:`DssSync.stats`, never raised: the store keeps serving the
intent (with its local reference, as without a DSS, for a version the DSS does not hold) and the
put or delete is tried again at the next pass that retries (:meth:`sync_once`). A notification
that fails is counted and not sent again.

:meth:`sync_once` is one pass, synchronous (the tests call it); :meth:`start` runs the passes in
a thread of their own, woken by every change of the store (``IntentStore.on_change``), with
retries every ``retry_s`` seconds. Times in the passes are the store's; the thread's wall clock only
paces the retries.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass
from datetime import datetime
from urllib.parse import urlsplit

from .dss import DssError

SCOPE_INTENTS = "utm.strategic_coordination"
SCOPE_CONSTRAINTS = "utm.constraint_processing"
#: consecutive volumes one extent bounds (12 pieces of 5 s: a minute of flight)
DEFAULT_GROUP = 12
#: at most this many extents per reference (longer flights get larger groups)
MAX_EXTENTS = 64
STATS = ("created", "updated", "deleted", "key_retries", "failures", "conflicts", "notified",
         "notify_failures", "peer_ovn_failures")


# ---- extents ---------------------------------------------------------------------------------

def _instant(t: dict, where: str) -> datetime:
    try:
        return datetime.fromisoformat(str(t["value"]).replace("Z", "+00:00"))
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {t!r} is not an RFC 3339 time ({exc})") from None


def bounding_volume(volumes: list, where: str = "volumes") -> dict:
    """One Volume4D (JSON) holding every Volume4D of ``volumes`` (JSON, outline polygons with W84
    altitudes and both times): the convex hull of their outlines (in latitude and longitude),
    their lowest and highest altitudes, their earliest start and latest end. ValueError naming the
    volume and field for one without a polygon, an altitude or a time."""
    from shapely.geometry import MultiPoint

    pts, lows, highs, starts, ends = [], [], [], [], []
    for k, v in enumerate(volumes):
        at = f"{where}[{k}]"
        vol3 = v.get("volume") or {}
        poly = vol3.get("outline_polygon")
        if not poly or len(poly.get("vertices") or []) < 3:
            raise ValueError(f"{at}.volume.outline_polygon: {str(poly)[:80]!r} is not a polygon of 3+ vertices")
        pts += [(float(p["lng"]), float(p["lat"])) for p in poly["vertices"]]
        for name, out in (("altitude_lower", lows), ("altitude_upper", highs)):
            alt = vol3.get(name)
            if not alt or alt.get("reference") != "W84" or alt.get("units") != "M":
                raise ValueError(f"{at}.volume.{name}: {alt!r} is not a W84 altitude in M")
            out.append(float(alt["value"]))
        starts.append((_instant(v.get("time_start"), f"{at}.time_start"), v["time_start"]))
        ends.append((_instant(v.get("time_end"), f"{at}.time_end"), v["time_end"]))
    if not pts:
        raise ValueError(f"{where}: empty (a reference needs at least one extent)")
    hull = MultiPoint(pts).convex_hull
    if hull.geom_type != "Polygon":
        raise ValueError(f"{where}: the outlines span no area ({hull.geom_type})")
    ring = list(hull.exterior.coords)[:-1]
    return {"volume": {"outline_polygon": {"vertices": [{"lat": lat, "lng": lng} for lng, lat in ring]},
                       "altitude_lower": {"value": min(lows), "reference": "W84", "units": "M"},
                       "altitude_upper": {"value": max(highs), "reference": "W84", "units": "M"}},
            "time_start": dict(min(starts, key=lambda s: s[0])[1]),
            "time_end": dict(max(ends, key=lambda e: e[0])[1])}


def extents_of(volumes_json, group: int = DEFAULT_GROUP, max_extents: int = MAX_EXTENTS) -> list:
    """The extents of a reference whose details hold the volumes ``volumes_json`` (JSON texts):
    one :func:`bounding_volume` per ``group`` consecutive volumes (more when there would be over
    ``max_extents``), so every volume lies inside an extent. ``group`` 1: the volumes' own
    outlines."""
    if int(group) < 1:
        raise ValueError(f"group: {group!r} is not a count of volumes >= 1")
    vols = [json.loads(v) for v in volumes_json]
    if not vols:
        raise ValueError("volumes: empty (a reference needs at least one extent)")
    size = max(int(group), math.ceil(len(vols) / max(1, int(max_extents))))
    return [bounding_volume(vols[i:i + size], f"volumes[{i}:{i + size}]") for i in range(0, len(vols), size)]


# ---- the sync ---------------------------------------------------------------------------------

@dataclass
class _Held:
    """What the DSS holds of one intent, as this USS knows it."""
    version: int | None = None     # the local version the DSS's reference is of; None: no reference
    plan_version: int = 0
    ovn: str = ""
    subscription_id: str = ""
    failed: int | None = None      # the local version whose last put failed (retried on a retry pass)
    failed_plan: int = 0
    delete_failed: bool = False


def _as_json(obj) -> dict:
    return json.loads(json.dumps(obj, default=str))


def _missing(exc: DssError) -> list:
    """(kind, reference) of every reference a 409's AirspaceConflictResponse names."""
    c = exc.conflict
    if exc.status != 409 or c is None:
        return []
    return ([("intent", r) for r in (c.get("missing_operational_intents") or [])]
            + [("constraint", r) for r in (c.get("missing_constraints") or [])])


class DssSync:
    """The references of ``store``'s intents kept in the DSS of ``client`` (module docstring).

    ``tokens``: the token source for peers (notifications, their OVNs; default the client's),
    asked for a token with the peer's host as audience; ``session``: the HTTP session for peers
    (requests-like, default a ``requests.Session``); ``log`` / ``warn``: one line per change /
    failure; ``group``: :func:`extents_of`'s. ``stats`` counts (:data:`STATS`): references
    created, updated, deleted; puts retried with the key a 409 asked for; failures (no answer,
    an error) and conflicts (a 409 after the retry); notifications sent and failed; peers' OVNs
    that could not be read."""

    def __init__(self, store, client, tokens=None, session=None, log=None, warn=None,
                 group: int = DEFAULT_GROUP, timeout_s: float = 10.0):
        if int(group) < 1:
            raise ValueError(f"group: {group!r} is not a count of volumes >= 1")
        if session is None:
            import requests
            session = requests.Session()
        self.store, self.client = store, client
        self.tokens = tokens if tokens is not None else client.tokens
        self._session, self.group, self.timeout_s = session, int(group), float(timeout_s)
        self.log = log or (lambda text: None)
        self.warn = warn or self.log
        self.stats = dict.fromkeys(STATS, 0)
        self._held: dict[str, _Held] = {}
        self._cond = threading.Condition()
        self._pass = threading.Lock()
        self._wake = threading.Event()
        self._stopped = threading.Event()
        self._thread = None

    # ---- one pass -----------------------------------------------------------------------------
    def sync_once(self, retry: bool = True) -> None:
        """Bring the DSS in step with the store: create, update or delete each reference that
        differs. ``retry`` False: a put or delete that failed at the same version is left for a
        later pass that retries."""
        with self._pass:
            views = {v.entity_id: v for v in self.store.views()}
            for oid, view in views.items():
                held = self._held.get(oid)
                if held is not None and held.version == view.version:
                    continue
                if held is not None and held.failed == view.version and not retry:
                    continue
                self._put(view, held)
            for oid in [k for k in self._held if k not in views]:
                held = self._held[oid]
                if not (held.delete_failed and not retry):
                    self._delete(oid, held)

    def held(self, entity_id: str):
        """(the local version the DSS holds, its OVN) for ``entity_id``, or None."""
        with self._cond:
            h = self._held.get(entity_id)
            return None if h is None or h.version is None else (h.version, h.ovn)

    def _set_held(self, entity_id: str, held: _Held | None) -> None:
        with self._cond:
            if held is None:
                self._held.pop(entity_id, None)
            else:
                self._held[entity_id] = held
            self._cond.notify_all()

    def _put(self, view, held: _Held | None) -> None:
        """Create or update the reference of ``view``; the DSS's reference served; subscribers
        notified. A failure is logged, counted and remembered for a retry."""
        new = held is None or held.version is None
        try:
            answer, created = self._put_keyed(view, extents_of(view.volumes_json, self.group), held)
        except (DssError, ValueError, OSError) as exc:
            conflict = isinstance(exc, DssError) and exc.status == 409
            self.stats["conflicts" if conflict else "failures"] += 1
            kept = (f"the DSS holds version {held.version} (OVN {held.ovn})" if not new
                    else "the DSS holds no reference of it")
            self.warn(f"DSS: operational intent {view.entity_id} version {view.version} ({view.state}) not "
                      f"{'created' if new else 'updated'}: {exc}; served with its local reference, {kept}; "
                      "tried again at the next retry")
            failed = held if held is not None else _Held()
            failed.failed, failed.failed_plan = view.version, view.plan_version
            self._set_held(view.entity_id, failed)
            return
        ref = _as_json(answer.operational_intent_reference)
        self.store.set_reference(view.entity_id, view.version, ref)
        self._set_held(view.entity_id, _Held(view.version, view.plan_version, str(ref["ovn"]),
                                             str(ref.get("subscription_id") or "")))
        self.stats["created" if created else "updated"] += 1
        self.log(f"DSS: operational intent {view.entity_id} {'created' if created else 'updated'}: local version "
                 f"{view.version} ({view.state}) is DSS version {ref['version']}, OVN {ref['ovn']}")
        self._notify(answer.get("subscribers") or [], view.entity_id,
                     self.store.document(view, json.dumps(ref, separators=(",", ":"))))

    def _put_keyed(self, view, extents: list, held: _Held | None) -> tuple:
        """(the DSS's answer, created) of the put of ``view``: an update at the held OVN, or a
        create; a create of an id the DSS has (a reference this USS left, e.g. in an earlier run:
        the ids are the same every run) becomes an update at its OVN; an update the DSS no longer
        knows (404) becomes a create."""
        key = self._key(extents)
        ovn = held.ovn if held is not None and held.version is not None else None
        sub = held.subscription_id if ovn else None
        try:
            return self._keyed(view, extents, key, ovn, sub), ovn is None
        except DssError as exc:
            if exc.status == 409 and ovn is None and not _missing(exc):
                found = _as_json(self.client.get_operational_intent_reference(view.entity_id))
                if not found.get("ovn"):   # another manager's: only its manager sees the OVN
                    raise
                self.log(f"DSS: operational intent {view.entity_id}: a reference of this USS is there already "
                         f"(version {found.get('version')}); updated")
                return self._keyed(view, extents, key, found["ovn"], found.get("subscription_id")), False
            if exc.status == 404 and ovn is not None:
                self.warn(f"DSS: operational intent {view.entity_id}: the DSS no longer has its reference "
                          f"(OVN {ovn}); created again")
                return self._keyed(view, extents, key, None, None), True
            raise

    def _keyed(self, view, extents: list, key: list, ovn: str | None, sub: str | None):
        """One put; on a 409 naming references whose OVNs the key lacked, once more with them."""
        def put(k):
            return self.client.put_operational_intent_reference(
                view.entity_id, extents, view.state, self.store.ctx.uss_base_url, key=k, ovn=ovn,
                subscription_id=sub)
        try:
            return put(key)
        except DssError as exc:
            missing = _missing(exc)
            if not missing:
                raise
            self.stats["key_retries"] += 1
            more = self._ovns(missing)
            self.log(f"DSS: operational intent {view.entity_id}: the key lacked {len(missing)} reference(s) "
                     f"({', '.join(str(r['id']) for _, r in missing)}); put again with {len(more)} more OVN(s)")
            return put(sorted(set(key) | set(more)))

    def _key(self, extents: list) -> list:
        """The OVNs of every operational intent and constraint reference meeting the extents'
        bounding volume."""
        area = bounding_volume(extents, "extents")
        refs = [("intent", r) for r in self.client.query_operational_intent_references(area)]
        refs += [("constraint", r) for r in self.client.query_constraint_references(area)]
        return sorted(set(self._ovns(refs)))

    def _ovns(self, refs: list) -> list:
        """The OVN of each (kind, reference): its own ``ovn`` (the DSS shows it to its manager),
        else read from its USS's details endpoint; a USS that does not answer is logged, counted
        and left out (the DSS will then refuse the key)."""
        out = []
        for kind, ref in refs:
            ovn = ref.get("ovn") or self._peer_ovn(kind, ref)
            if ovn:
                out.append(str(ovn))
        return out

    def _peer_ovn(self, kind: str, ref) -> str:
        base = str(ref.get("uss_base_url") or "").rstrip("/")
        what, field, scope = (("operational_intents", "operational_intent", SCOPE_INTENTS) if kind == "intent"
                              else ("constraints", "constraint", SCOPE_CONSTRAINTS))
        url = f"{base}/uss/v1/{what}/{ref['id']}"
        try:
            r = self._session.request("GET", url, headers=self._auth(base, scope), timeout=self.timeout_s)
            if r.status_code != 200:
                raise ValueError(f"HTTP {r.status_code}: {r.text[:200]}")
            return str(r.json()[field]["reference"]["ovn"])
        except Exception as exc:   # noqa: BLE001 - a peer's failure of any kind is logged and counted
            self.stats["peer_ovn_failures"] += 1
            self.warn(f"DSS: the OVN of {kind} {ref['id']} could not be read from {url}: {exc}")
            return ""

    def _auth(self, base_url: str, scope: str) -> dict:
        return {"Authorization": f"Bearer {self.tokens.token(urlsplit(base_url).hostname or '', [scope])}"}

    def _delete(self, entity_id: str, held: _Held) -> None:
        """Delete the reference of an intent no longer served; notify its subscribers."""
        if held.version is None:   # the DSS never had it
            self._set_held(entity_id, None)
            return
        try:
            answer = self.client.delete_operational_intent_reference(entity_id, held.ovn)
        except DssError as exc:
            if exc.status == 404:
                self.log(f"DSS: operational intent {entity_id}: its reference is gone already")
                self._set_held(entity_id, None)
                return
            self.stats["failures"] += 1
            self.warn(f"DSS: operational intent {entity_id}: its reference (OVN {held.ovn}) not deleted: {exc}; "
                      "tried again at the next retry")
            held.delete_failed = True
            self._set_held(entity_id, held)
            return
        self._set_held(entity_id, None)
        self.stats["deleted"] += 1
        self.log(f"DSS: operational intent {entity_id}: reference deleted")
        self._notify(answer.get("subscribers") or [], entity_id, None)

    # ---- notifications ----------------------------------------------------------------------
    def _notify(self, subscribers, entity_id: str, document: str | None) -> None:
        """POST the intent (or its deletion: ``document`` None) to every subscriber but this USS."""
        own = self.store.ctx.uss_base_url.rstrip("/")
        for s in subscribers:
            base = str(s.uss_base_url).rstrip("/")
            if base == own:
                continue
            body = {"operational_intent_id": entity_id,
                    "subscriptions": [{"subscription_id": str(x.subscription_id),
                                       "notification_index": int(x.notification_index)} for x in s.subscriptions]}
            if document is not None:
                body["operational_intent"] = json.loads(document)
            url = f"{base}/uss/v1/operational_intents"
            try:
                r = self._session.request("POST", url, json=body, headers=self._auth(base, SCOPE_INTENTS),
                                          timeout=self.timeout_s)
                problem = "" if r.status_code in (200, 204) else f"HTTP {r.status_code}: {r.text[:200]}"
            except Exception as exc:   # noqa: BLE001 - a subscriber's failure of any kind is counted
                problem = str(exc)
            if problem:
                self.stats["notify_failures"] += 1
                self.warn(f"DSS: subscriber {base} not notified of operational intent {entity_id}: {problem}")
            else:
                self.stats["notified"] += 1

    # ---- in a thread ----------------------------------------------------------------------------
    def wait_settled(self, entity_id: str, plan_version: int | None, timeout_s: float) -> str:
        """Wait (at most ``timeout_s`` s) until the DSS holds a reference of ``entity_id`` at plan
        version ``plan_version`` or later ('synced') or its put failed ('failed'); with
        ``plan_version`` None, until it holds none ('deleted') or the delete failed ('failed').
        'timeout' otherwise."""
        def outcome() -> str:
            h = self._held.get(entity_id)
            if plan_version is None:
                return "deleted" if h is None or h.version is None else ("failed" if h.delete_failed else "")
            if h is not None and h.version is not None and h.plan_version >= int(plan_version):
                return "synced"
            return "failed" if h is not None and h.failed is not None and h.failed_plan >= int(plan_version) else ""
        with self._cond:
            self._cond.wait_for(outcome, timeout=timeout_s)
            return outcome() or "timeout"

    def start(self, retry_s: float = 5.0) -> "DssSync":
        """Run the passes in a daemon thread: at every change of the store, and with retries every
        ``retry_s`` seconds."""
        if not retry_s > 0:
            raise ValueError(f"retry_s: {retry_s!r} is not a time > 0 s")
        self.store.on_change = self._wake.set
        self._thread = threading.Thread(target=self._run, args=(float(retry_s),), name="dss-sync", daemon=True)
        self._thread.start()
        self._wake.set()
        return self

    def _run(self, retry_s: float) -> None:
        last_retry = time.monotonic()
        while not self._stopped.is_set():
            self._wake.wait(retry_s)
            self._wake.clear()
            if self._stopped.is_set():
                break
            retry = time.monotonic() - last_retry >= retry_s
            if retry:
                last_retry = time.monotonic()
            try:
                self.sync_once(retry)
            except Exception as exc:   # noqa: BLE001 - the thread outlives any one pass
                self.stats["failures"] += 1
                self.warn(f"DSS: a sync pass failed: {exc!r}")

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stopped.set()
        self._wake.set()
        if self.store.on_change == self._wake.set:
            self.store.on_change = None
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)
