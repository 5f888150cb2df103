"""Export a recording's plans as ASTM F3548 operational intents, every version
(docs/f3548.md).

    python -m uam_sim.export_f3548 RUN.mcap --out DIR [--network FILE] [--piece-s 5]

writes

- ``DIR/operational_intents/<id>_v<version>.json``: one ``GetOperationalIntentDetailsResponse``
  per plan version of the run's record (``uam_sim.audit.record``, as the analysis builds it from
  ``uam/flight_plans``: forged plans left out), as known at its decision (the plan's stamp):
  its state there (the FlightPlan's ``state`` where it has one, else
  ``uam_planner.replanning.flight_state``), every volume of the version, and the F3548
  version of that plan version and state (``uam_planner.f3548.intent_version``);
- ``DIR/constraints/<id>_v<version>.json``: one ``GetConstraintDetailsResponse`` per version of
  every prism constraint the planner published on ``uam/constraints`` (closures have no F3548
  form and are listed in the index only);
- ``DIR/index.json``: every intent version (id, operator, request, version, state, decided_s,
  file; a cancellation as state ``Ended`` without a file) and every constraint version, the
  scenario's UTC start, the separation model and the volume spec.

Every document is checked against the F3548 schema (``uam_planner.f3548_schema``) before it is
written; an invalid one stops the export naming it. The network (for the origin that places the
volumes on WGS84) is ``--network`` (the recording does not hold it); the separation model is
the recording's ``uam_airspace`` metadata; the UTC instant of simulation time 0 is the
recording's ``uam_clock`` (``log_time_start_utc``), else ``--scenario-start-utc``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Callable
from datetime import datetime, timedelta, timezone
from pathlib import Path

from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC, stamp_s

STATES = {1: "Accepted", 2: "Activated", 3: "Nonconforming", 4: "Contingent", 5: "Ended"}


def _utc_text(ns: int) -> str:
    when = datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=ns // 1000)
    return when.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _flight(msg, version: int, priority: int):
    """The planner's Flight of a recorded FlightPlan (what uam_planner.nodes.conversions does,
    which this library may not import: docs/architecture.md)."""
    import numpy as np

    from uam_planner.planning import Flight
    from uam_planner.trajectory import Trajectory

    t = np.array([stamp_s(w.time) for w in msg.waypoints], dtype=np.float64)
    x = np.array([(w.position.x, w.position.y, w.position.z) for w in msg.waypoints],
                 dtype=np.float64).reshape(-1, 3)
    traj = Trajectory(t, x)
    return Flight(msg.request_id, msg.origin_id, msg.destination_id, tuple(msg.route_node_ids), traj,
                  stamp_s(msg.departure_time), stamp_s(msg.arrival_time), float(msg.length_m),
                  float(msg.weight), int(msg.candidate_index), str(msg.method), str(msg.backend),
                  int(msg.epoch_index), priority=int(priority), operator_id=msg.operator_id,
                  version=version, contingent=int(getattr(msg, "state", 0) or 0) == 4,
                  effective_s=stamp_s(msg.effective_time) if version > 1 else float("nan"))


def _intent_row(msg, ctx, out: Path, priority: int, operational_intent, as_json, validate, intent_id) -> dict:
    """The index row of one plan version, its document written (a cancellation: Ended, no file)."""
    version = max(1, int(getattr(msg, "version", 0) or 0))
    oid = intent_id(msg.operator_id, msg.request_id)
    decided = stamp_s(msg.header.stamp)
    row = {"id": oid, "operator_id": msg.operator_id, "request_id": msg.request_id,
           "version": version, "decided_s": decided, "state": None, "file": None}
    if msg.outcome != msg.OUTCOME_APPROVED or not msg.waypoints:
        row["state"] = "Ended"  # a cancelled version
        return row
    f = _flight(msg, version, priority)
    state = STATES.get(int(getattr(msg, "state", 0) or 0))
    oi = operational_intent(f, decided, ctx, state=state if state != "Ended" else None)
    if oi is None:
        row["state"] = "Ended"
        return row
    body = {"operational_intent": as_json(oi)}
    try:
        validate(body, "GetOperationalIntentDetailsResponse")
    except ValueError as exc:
        raise ValueError(f"{msg.operator_id}/{msg.request_id} v{version}: {exc}") from None
    row["state"] = oi.reference.state
    row["file"] = f"operational_intents/{oid}_v{version}.json"
    (out / row["file"]).write_text(json.dumps(body, separators=(",", ":")))
    return row


def export(recording, out_dir, network_file: str, piece_s: float = 5.0,
           scenario_start_utc: str | None = None, progress: Callable[[str], None] | None = None) -> dict:
    """Write the F3548 documents of ``recording`` into ``out_dir``; returns the index.
    ``progress(text)``, if given, hears each step and the intents written so far (an hour's
    recording takes about a minute)."""
    say = progress or (lambda text: None)
    from uam_planner.f3548 import (IntentContext, VolumeSpec, as_json, constraint_entity_id,
                                   f3548_constraint, intent_id, operational_intent)
    from uam_planner.f3548_schema import validate
    from uam_planner.live_constraints import constraints_from_text
    from uam_planner.network import load_network

    from ..audit.analysis import TOPIC_CONSTRAINTS, TOPIC_REQUESTS, summarize
    from ..audit.separation import AIRSPACE_METADATA, separation_from_metadata
    from ..recording.mcap_reader import iter_decoded, log_time_zero_ns, read_metadata, require_mcap

    path = Path(recording)
    if not path.is_file():
        raise FileNotFoundError(f"recording: no file at {path}")
    require_mcap(path)
    network = load_network(network_file)
    model = separation_from_metadata(read_metadata(path, AIRSPACE_METADATA), 100.0)
    zero = log_time_zero_ns(path)
    start = scenario_start_utc or (_utc_text(zero) if zero > 0 else DEFAULT_SCENARIO_START_UTC)
    spec = VolumeSpec.for_separation(model, piece_s)
    ctx = IntentContext.for_network(network, spec, scenario_start_utc=start)
    out = Path(out_dir)
    (out / "operational_intents").mkdir(parents=True, exist_ok=True)
    (out / "constraints").mkdir(parents=True, exist_ok=True)
    say("reading the requests and constraints")
    priority: dict = {}
    constraints, seen_c = [], set()
    for topic, _t_ns, msg in iter_decoded(path, "rclpy", [TOPIC_REQUESTS, TOPIC_CONSTRAINTS]):
        if topic == TOPIC_REQUESTS:
            priority[(msg.operator_id, msg.request_id)] = int(getattr(msg, "priority", 0))
            continue
        t_s, pairs = constraints_from_text(msg.data, network)
        for con, _eff in pairs:
            key = (con.constraint_id, con.version)
            if key in seen_c:
                continue
            seen_c.add(key)
            cid = constraint_entity_id(con.constraint_id)
            row = {"id": cid, "constraint_id": con.constraint_id, "version": con.version,
                   "published_s": t_s, "file": None}
            doc = f3548_constraint(con, ctx)
            if doc is not None:
                body = {"constraint": as_json(doc)}
                validate(body, "GetConstraintDetailsResponse")
                row["file"] = f"constraints/{cid}_v{con.version}.json"
                (out / row["file"]).write_text(json.dumps(body, indent=1))
            constraints.append(row)
    # the intents are the run's record (uam_sim.audit.record, as the analysis builds it): every
    # approval that is not forged, each of its versions once
    say(f"{len(constraints)} constraint versions; reading the plans (the run's record, as the analysis does)")
    record = summarize(path, network=network, flown=False).record
    total = sum(len(flight.versions) for flight in record.flights)
    say(f"writing {total} plan versions as operational intents")
    intents = []
    last = time.monotonic()
    for flight in record.flights:
        for msg in flight.versions:
            intents.append(_intent_row(msg, ctx, out, priority.get((msg.operator_id, msg.request_id), 0),
                                       operational_intent, as_json, validate, intent_id))
            if time.monotonic() - last >= 5.0:
                last = time.monotonic()
                say(f"{len(intents)} of {total} plan versions written")
    index = {"recording": str(path), "network": str(network_file), "scenario_start_utc": start,
             "separation": {"kind": model.kind, "separation_m": model.separation_m,
                            "vertical_separation_m": model.vertical_separation_m},
             "volume_spec": {"horizontal_buffer_m": spec.horizontal_buffer_m,
                             "vertical_buffer_m": spec.vertical_buffer_m,
                             "max_piece_s": spec.max_piece_s},
             "operational_intents": intents, "constraints": constraints}
    (out / "index.json").write_text(json.dumps(index, indent=1))
    return index


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m uam_sim.export_f3548",
                                 description="Write a recording's plans (every version) and "
                                             "constraints as ASTM F3548 JSON documents.")
    ap.add_argument("recording", help="the run's .mcap")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--network", default="config/networks/singapore.yaml",
                    help="the run's network file (its origin places the volumes)")
    ap.add_argument("--piece-s", type=float, default=5.0, help="longest window of one volume [s]")
    ap.add_argument("--scenario-start-utc", default=None,
                    help="UTC of simulation time 0 (default: the recording's, else "
                         f"{DEFAULT_SCENARIO_START_UTC})")
    args = ap.parse_args(argv)
    t0 = time.monotonic()

    def progress(text: str) -> None:
        print(f"export_f3548: [{time.monotonic() - t0:.0f} s] {text}", file=sys.stderr, flush=True)

    try:
        index = export(args.recording, args.out, args.network, args.piece_s, args.scenario_start_utc,
                       progress=progress)
    except (ValueError, OSError) as exc:
        print(f"export_f3548: {exc}", file=sys.stderr)
        return 2
    files = sum(1 for r in index["operational_intents"] if r["file"])
    # the constraint versions the index lists; closures have no F3548 form (no document)
    documents = sum(1 for r in index["constraints"] if r["file"])
    print(f"export_f3548: {files} operational intent versions "
          f"({len({r['id'] for r in index['operational_intents']})} intents), "
          f"{len(index['constraints'])} constraint versions ({documents} as F3548 constraint documents, "
          f"{len(index['constraints']) - documents} closures without one) in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
