"""The MWIS instances a planner solved, read back from the PlanningReports of a recording.

Also the ``.mcap`` corpus reader of ``uam_solvers.instances`` (:func:`corpus_entries`), which
finds it through the entry point ``mcap`` of group ``uam_solvers.corpus_readers`` declared in
this package's setup.py: the solver library reads recordings without importing this package.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from uam_contract.stamps import stamp_s
from uam_contract import names
from uam_contract.names import resolved
from .mcap_reader import iter_decoded

TOPIC_REPORTS = resolved(names.TOPIC_REPORTS)


@dataclass
class RecordedInstance:
    """An MWIS instance as the planner solved it in one epoch, with its answer."""

    epoch_index: int
    t_s: float
    problem: Any                      # uam_solvers.base.MwisProblem
    vertex_request_ids: list
    vertex_candidate_index: list
    selected: list
    objective: float
    solve_time_s: float
    backend_used: str


def recorded_instances(path: str | Path, reader: str = "rclpy") -> list[RecordedInstance]:
    """Every non-empty MWIS instance of the PlanningReports, in epoch order.

    The problem's clique groups are the vertices of each request (at most one candidate per
    request), in addition to the recorded edges.
    """
    from uam_solvers.base import MwisProblem

    out = []
    for _topic, _t_ns, msg in iter_decoded(path, reader, topics=(TOPIC_REPORTS,)):
        inst = msg.instance
        weights = np.asarray(inst.weights, dtype=np.float64)
        if weights.size == 0:
            continue
        edges = np.stack([np.asarray(inst.edges_u, dtype=np.int64),
                          np.asarray(inst.edges_v, dtype=np.int64)], axis=1).reshape(-1, 2)
        rids = [str(r) for r in inst.vertex_request_ids]
        groups: dict[str, list[int]] = {}
        for i, r in enumerate(rids):
            groups.setdefault(r, []).append(i)
        problem = MwisProblem.from_arrays(weights, edges, groups=list(groups.values()) if rids else None)
        out.append(RecordedInstance(
            epoch_index=int(msg.epoch_index), t_s=stamp_s(msg.header.stamp), problem=problem,
            vertex_request_ids=rids, vertex_candidate_index=[int(c) for c in inst.vertex_candidate_index],
            selected=[int(s) for s in inst.selected], objective=float(msg.objective),
            solve_time_s=float(msg.solve_time_s), backend_used=str(msg.backend_used)))
    return sorted(out, key=lambda r: r.epoch_index)


def instances_from_mcap(path: str | Path, reader: str = "rclpy") -> list:
    """The MWIS instances of a recording as ``uam_solvers.base.MwisProblem`` objects."""
    return [r.problem for r in recorded_instances(path, reader)]


def corpus_entries(path: str | Path) -> list:
    """``uam_solvers.instances.CorpusEntry`` per recorded instance (the ``.mcap`` corpus reader)."""
    from uam_solvers.instances import CorpusEntry

    path = Path(path)
    return [CorpusEntry(f"{path.stem}-epoch{r.epoch_index}", r.problem, source=f"{path}#epoch={r.epoch_index}")
            for r in recorded_instances(path)]
