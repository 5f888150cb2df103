"""One launcher truth (issue 19): scripts/run_fleet.sh and launch/uam.launch.py have the same
options, from one table (uam_contract.launch_options). The launch file builds its arguments from
the table; here run_fleet.sh's flags, shell variables, defaults and usage text are held to it,
and every launch argument must be used by the launch file. Read from the sources: no launch
package is needed (the PyPI wheels do not ship it)."""

from __future__ import annotations

import pathlib
import re
import shlex

from uam_contract.launch_options import LAUNCH_OPTIONS

ROOT = pathlib.Path(__file__).resolve().parents[1]
RUN_FLEET = (ROOT / "scripts" / "run_fleet.sh").read_text()
LAUNCH = (ROOT / "src" / "uam_bringup" / "launch" / "uam.launch.py").read_text()


def _case_arms() -> dict[str, str]:
    """run_fleet.sh's option parser: flag -> the shell variable it sets."""
    return dict(re.findall(r"^\s+(--[a-z-]+)\) ([A-Z_]+)=", RUN_FLEET, re.M))


def _defaults() -> dict[str, str]:
    """The shell variables' defaults: the assignment lines before the option parser."""
    head = RUN_FLEET.split("while [[ $# -gt 0 ]]", 1)[0]
    out = {}
    for line in head.splitlines():
        if re.match(r"^[A-Z_]+=", line):
            for word in shlex.split(line):
                name, _, value = word.partition("=")
                out[name] = value
    return out


def _usage_flags() -> set[str]:
    usage = RUN_FLEET.split("set -Eeuo pipefail", 1)[0]
    return set(re.findall(r"(?:^#\s+|, )(--[a-z][a-z-]*)", usage, re.M))


def test_every_run_fleet_option_is_in_the_table_with_its_variable_and_default():
    arms, defaults = _case_arms(), _defaults()
    table = {o.flag: o for o in LAUNCH_OPTIONS if o.only != "launch"}
    assert set(arms) == set(table), (sorted(set(arms) - set(table)), sorted(set(table) - set(arms)))
    for flag, option in table.items():
        assert arms[flag] == option.var, (flag, arms[flag], option.var)
        assert defaults.get(option.var) == option.default, (flag, defaults.get(option.var), option.default)


def test_run_fleet_usage_names_every_option():
    assert {o.flag for o in LAUNCH_OPTIONS if o.only != "launch"} <= _usage_flags(), \
        sorted({o.flag for o in LAUNCH_OPTIONS if o.only != "launch"} - _usage_flags())


def test_the_launch_file_takes_its_arguments_from_the_table_and_uses_every_one():
    assert "ARGS = {o.arg: (o.default, o.help) for o in LAUNCH_OPTIONS if o.only != \"run_fleet\"}" in LAUNCH
    used = set(re.findall(r'a\["([a-z_]+)"\]', LAUNCH))
    declared = {o.arg for o in LAUNCH_OPTIONS if o.only != "run_fleet"}
    assert declared - used == set(), f"launch arguments declared but not used: {sorted(declared - used)}"
    assert used - declared == set(), sorted(used - declared)


def test_the_table_is_seen_by_the_test():
    """The checks above would pass on an empty table: it holds the options users know."""
    flags = {o.flag for o in LAUNCH_OPTIONS}
    assert {"--backend", "--separation", "--climb-rate", "--foxglove-port", "--out"} <= flags
    assert len(_case_arms()) >= 18 and _defaults()["BACKEND"] == "exact"
