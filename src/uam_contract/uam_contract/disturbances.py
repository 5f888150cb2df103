"""Whether a run's flights can leave their plans: the rule ``scripts/run_fleet.sh`` and the launch
file read to start the conformance monitor with ``--conformance auto``. It is the simulator's
disturbance model's rule (``uam_sim.world.disturbance.DisturbanceConfig.enabled``: any level of a
registered effect not 0) for its built-in effects: LEVELS are their levels, in their registration
order (held equal by src/uam_sim/test/test_disturbance_conformance.py; this package, the lowest
layer, does not import the simulator). A plugin effect's level is not here: the launchers do not
pass it.

    python -m uam_contract.disturbances CONFORMANCE REACTION WIND GUST SPEED_ERROR DELAY_MEAN \
        VERTICAL_GUST ALTITUDE_ERROR        # prints true or false: start the monitor?
"""

from __future__ import annotations

import sys

#: the disturbance levels, in the order the functions below take them; any of them non-zero
#: makes the fleet fly off its plans
LEVELS = ("wind_speed_mps", "gust_std_mps", "speed_error", "delay_mean_s", "vertical_gust_std_mps",
          "altitude_error_m")


def disturbances_on(*levels) -> bool:
    """True when any of the levels (numbers, or their text; LEVELS order) is not 0.

    >>> disturbances_on(0, 0, 0.1, 0, 0, 0), disturbances_on("0", "0.0", 0, 0, 0, 0)
    (True, False)
    """
    if len(levels) != len(LEVELS):
        raise ValueError(f"disturbance levels: {len(levels)} given, {len(LEVELS)} expected ({', '.join(LEVELS)})")
    values = []
    for name, value in zip(LEVELS, levels):
        try:
            values.append(float(value))
        except (TypeError, ValueError):
            raise ValueError(f"{name}: {value!r} is not a number") from None
    return any(v != 0.0 for v in values)


def conformance_monitor_on(conformance: str, reaction, *levels) -> bool:
    """Whether the conformance monitor runs: ``conformance`` 'true', or 'auto' when a
    disturbance is on or the planner reacts to its reports (``reaction`` true or 'true').

    >>> conformance_monitor_on("auto", "false", 0, 0, 0, 0, 0, 0)
    False
    >>> conformance_monitor_on("auto", "true", 0, 0, 0, 0, 0, 0), conformance_monitor_on("true", False, *[0] * 6)
    (True, True)
    """
    if conformance not in ("auto", "true", "false"):
        raise ValueError(f"conformance: {conformance!r} is not auto, true or false")
    if conformance != "auto":
        return conformance == "true"
    return str(reaction).lower() == "true" or disturbances_on(*levels)


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        print("true" if conformance_monitor_on(args[0], args[1], *args[2:]) else "false")
    except (IndexError, ValueError) as exc:
        print(f"uam_contract.disturbances: {exc or 'CONFORMANCE REACTION and 6 levels expected'}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
