"""The one reader of the constraints files the runner (``--constraints``) and the planner node
(``constraints_file``) take: GeoJSON and ED-269 (:mod:`uam_planner.constraints`), and F3548
documents (another USS's operational intents, F3548 constraints: :mod:`uam_planner.f3548`).
It sits above both so that ``constraints`` never imports the F3548 module, which
builds on it (test/test_layering.py: no import cycles)."""

from __future__ import annotations

import json
from pathlib import Path

from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC

from .constraints import ConstraintError, ConstraintSet, constraint_set_from_document
from .f3548 import F3548Error, constraints_from_f3548, is_f3548_document


def load_airspace(path, network, now_s: float | None = None,
                  scenario_start_utc: str | None = None) -> ConstraintSet:
    """Read a constraints file of any supported form and check it against ``network`` (and
    ``now_s``, if given). Raises ConstraintError (a ValueError) naming the file and the field."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except OSError as exc:
        raise ConstraintError(f"constraints file {str(p)!r}: {exc}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConstraintError(f"constraints file {str(p)!r}: is not JSON ({exc}); a GeoJSON "
                              "FeatureCollection, an ED-269 zone file or an F3548 document is expected") from None
    if not is_f3548_document(doc):
        return constraint_set_from_document(doc, network, now_s, scenario_start_utc, str(p))
    try:
        found = constraints_from_f3548(doc, network, scenario_start_utc or DEFAULT_SCENARIO_START_UTC)
        return ConstraintSet(found, network, now_s)
    except (F3548Error, ConstraintError) as exc:
        raise ConstraintError(f"constraints file {str(p)!r}: {exc}") from None
