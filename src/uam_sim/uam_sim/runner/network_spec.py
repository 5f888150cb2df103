"""The network of a study: a file or a synthetic spec, its identity (for cell keys), loaded once
per process."""

from __future__ import annotations

import hashlib
import json

from .experiment_config import ExperimentError, resolve_path


def network_identity(spec) -> str:
    """A string that changes whenever the network would: file bytes hash or the synthetic spec."""
    if isinstance(spec, dict):
        return "synthetic:" + json.dumps(spec, sort_keys=True)
    p = resolve_path(str(spec))
    if not p.exists():
        raise ExperimentError(f"network: file {str(spec)!r} does not exist")
    return "file:" + hashlib.sha256(p.read_bytes()).hexdigest()


_NETWORKS: dict = {}


def load_network_spec(spec):
    """Load (and cache per process) the network named by ``spec`` (a path or a synthetic spec)."""
    key = json.dumps(spec, sort_keys=True) if isinstance(spec, dict) else str(spec)
    if key not in _NETWORKS:
        if isinstance(spec, dict):
            if set(spec) != {"synthetic"} or not isinstance(spec["synthetic"], dict):
                raise ExperimentError(f"network: {spec!r} must be a path or {{synthetic: {{...}}}}")
            from uam_planner.synthetic import generate_network
            _NETWORKS[key] = generate_network(**spec["synthetic"])
        else:
            from uam_planner.network import load_network
            p = resolve_path(str(spec))
            if not p.exists():
                raise ExperimentError(f"network: file {str(spec)!r} does not exist")
            _NETWORKS[key] = load_network(p)
    return _NETWORKS[key]
