"""The run's choices as the launchers write them for the recorder (its ``run_choices``
parameter, stored as the MCAP's ``uam_run`` metadata, which the analysis prints in its header):
one function for run_fleet.sh and the launch file.

    python -m uam_contract.run_choices policy=mwis backend=exact rate=10 ...

prints the JSON object; each value is read as JSON where it is (numbers, true/false), else kept
as text. A name outside :data:`NAMES` is refused, naming it.
"""

from __future__ import annotations

import json
import sys

#: the choices a run states, in the order the header prints them
NAMES = ("policy backend objective baseline_order rate seed priority_share horizon commit_ahead lead_time_s "
         "departure_slot_s spatial_buffer_m temporal_buffer_s reaction reaction_period_s probe_s probe_margin_m "
         "wind_mps wind_from_deg gust_mps speed_error delay_mean_s vertical_gust_mps altitude_error_m "
         "uss_auth").split()


def _value(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return text


def as_json(**given: str) -> str:
    """The JSON object of the run's choices (``given``: name -> its text as launched)."""
    unknown = sorted(set(given) - set(NAMES))
    if unknown:
        raise ValueError(f"run choices: {', '.join(unknown)} not among {' '.join(NAMES)}")
    return json.dumps({n: _value(str(given[n])) for n in NAMES if n in given}, separators=(",", ":"))


def main(argv=None) -> int:
    pairs = sys.argv[1:] if argv is None else argv
    try:
        bad = [p for p in pairs if "=" not in p]
        if bad:
            raise ValueError(f"run choices: {bad[0]!r} is not NAME=VALUE")
        print(as_json(**dict(p.split("=", 1) for p in pairs)))
    except ValueError as exc:
        print(f"uam_contract.run_choices: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
