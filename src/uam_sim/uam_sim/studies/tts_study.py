"""The TTS(0.99) study on a seeded sample of the MWIS instances a sweep collected, through
``uam_solvers.tts`` (reused when its sample and settings are unchanged)."""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..runner.experiment_config import ExperimentConfig
from ..runner.files import write_json_atomic


def sample_tts_corpus(entries: list, n: int, min_v: int, max_v: int, seed: int) -> list:
    """Up to n instances with min_v..max_v vertices, sampled without replacement (seeded)."""
    pool = [e for e in entries if min_v <= e.problem.n <= max_v]
    if len(pool) <= n:
        return pool
    idx = np.sort(np.random.default_rng(seed).choice(len(pool), size=n, replace=False))
    return [pool[i] for i in idx.tolist()]


def _available_backends(names: list) -> tuple[list, dict]:
    """The backends of ``names`` that are available here, in order, and the others with why."""
    from uam_solvers.registry import get_backend
    backends, unavailable = [], {}
    for b in names:
        try:
            ok, why = get_backend(b).available()
        except Exception as exc:  # unknown/broken backend: leave it out and say so
            ok, why = False, str(exc)
        if ok:
            backends.append(b)
        else:
            unavailable[b] = why
    return backends, unavailable


def _study_key(t: dict, sample: list, backends: list, caps: dict) -> str:
    """The SHA-256 of what decides a TTS study's rows: the sampled instances, the backends, their
    sub-sample caps, the reads, repetitions, seed and time limit [s]."""
    return hashlib.sha256(json.dumps(
        {"names": [e.name for e in sample], "backends": backends, "caps": caps,
         "reads": int(t["reads"]), "repetitions": int(t.get("repetitions", 5)),
         "seed": int(t.get("seed", 0)), "time_limit_s": float(t.get("time_limit_s", 10.0))},
        sort_keys=True).encode()).hexdigest()


def _cached_study(cache: Path, study_key: str) -> dict | None:
    """The result in ``cache`` (marked reused) when it is of ``study_key``, else None."""
    if cache.exists():
        try:
            cached = json.loads(cache.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            cached = {}
        if cached.get("key") == study_key:
            cached["result"]["reused"] = True
            return cached["result"]
    return None


def _measure(run_study, t: dict, sample: list, backends: list, caps: dict) -> tuple[list, list, float]:
    """Each backend's TTS rows on the sample (a capped backend on a seeded sub-sample of it), the
    instances skipped (each once) and the wall time of it all [s]."""
    t0 = time.perf_counter()
    rows, skipped = [], []
    for b in backends:
        # a slow backend may be studied on a seeded sub-sample of the same sample
        sub = sample_tts_corpus(sample, int(caps[b]), 0, 10**9, int(t.get("seed", 0)) + 1) \
            if b in caps else sample
        r, sk = run_study(sub, [b], repetitions=int(t.get("repetitions", 5)),
                          num_reads=int(t["reads"]), time_limit_s=float(t.get("time_limit_s", 10.0)),
                          seed=int(t.get("seed", 0)), log=lambda *a, **k: None)
        rows.extend(r)
        skipped.extend(x for x in sk if x not in skipped)
    return rows, skipped, time.perf_counter() - t0


def _nothing_measured(unavailable: dict, backends: list, skipped: list, sample: list, corpus) -> dict:
    """The skipped result of a study that produced no row, saying why."""
    why = []
    if unavailable:
        why.append("unavailable backends: " + "; ".join(f"{b} ({r})" for b, r in unavailable.items()))
    if not backends:
        why.append("no configured backend is available")
    if skipped:
        why.append(f"{len(skipped)} of {len(sample)} instances skipped (no proven optimum)")
    return {"status": "skipped", "corpus": str(corpus), "instances": len(sample),
            "reason": "nothing to measure (" + ", ".join(why or ["no row was produced"]) + ")"}


def run_tts(cfg: ExperimentConfig, entries: list) -> dict:
    """The TTS(p) study on a sample of the collected instances, through uam_solvers.tts.

    ``tts.source_seeds`` (optional list) restricts the pool to the runs of those seeds, so the
    study can start before the other seeds' runs finish and its sample does not change with them.
    Returns {"status": "ok"|"skipped", "reason", "csv", "rows", "corpus", "instances", ...}.
    """
    t = cfg.tts
    if not t.get("enabled", True):
        return {"status": "skipped", "reason": "disabled in the configuration (tts.enabled: false)"}
    if t.get("source_seeds") is not None:
        wanted = {int(x) for x in t["source_seeds"]}
        entries = [e for e in entries if int(e.name.rsplit("-s", 1)[1].split("-")[0]) in wanted]
    sample = sample_tts_corpus(entries, int(t["instances"]), int(t["min_vertices"]),
                               int(t["max_vertices"]), int(t.get("seed", 0)))
    if not sample:
        return {"status": "skipped", "reason": "no collected MWIS instance in the size range"}
    from uam_solvers.instances import save_corpus
    out = Path(cfg.out)
    corpus = save_corpus(out / "tts_corpus.jsonl", sample)
    try:
        from uam_solvers import tts as tts_mod
        run_study = tts_mod.run_study
    except (ImportError, AttributeError) as exc:
        return {"status": "skipped", "reason": f"uam_solvers.tts is not available ({exc})",
                "corpus": str(corpus), "instances": len(sample)}
    backends, unavailable = _available_backends(t["backends"])
    caps = dict(t.get("backend_instances") or {})
    # a finished study of the same sample and settings is reused (like a finished cell)
    study_key = _study_key(t, sample, backends, caps)
    cache = out / "tts_study.json"
    cached = _cached_study(cache, study_key)
    if cached is not None:
        return cached
    rows, skipped, wall = _measure(run_study, t, sample, backends, caps)
    if not rows:  # nothing was measured: say why instead of reporting an empty study
        return _nothing_measured(unavailable, backends, skipped, sample, corpus)
    tts_mod.write_csv(out / "tts.csv", rows)
    rows = [asdict(r) if hasattr(r, "__dataclass_fields__") else dict(r) for r in rows]
    result = {"status": "ok", "rows": rows, "csv": str(out / "tts.csv"), "corpus": str(corpus),
              "instances": len(sample), "skipped": skipped, "backends": backends,
              "unavailable": unavailable, "reads": int(t["reads"]),
              "repetitions": int(t.get("repetitions", 5)), "p": 0.99, "wall_s": wall,
              "backend_instances": caps}
    write_json_atomic(cache, {"key": study_key, "result": result})
    return result
