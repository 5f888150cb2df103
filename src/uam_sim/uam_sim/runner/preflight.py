"""A run's inputs checked before any node starts: every node parameter against the node's own
table (:mod:`uam_contract.params`, each ``Param.validate``) and every input file with the
library's own loader, in one process, so that a wrong value is refused in a second instead of
ending a started graph minutes later with the reason in one node's log.

    python -m uam_sim.preflight [--prog NAME] [--backend NAME] [--network FILE] [--demand FILE] \
        [--constraints FILE] --node NODE [--params-file YAML] [-p name:=value ...] [--node ...]

``--node`` opens the parameters of one node (a key of ``uam_contract.params.TABLES``): its
``--params-file`` (the ``ros__parameters`` under the node's name or ``/**``), then the ``-p``
overrides, read as ROS reads them (each value as YAML). The files are loaded as the nodes load
them: the network (``uam_planner.network.load_network``), the demand file against the network's
aerodromes and the generator's ``window_s`` (``uam_sim.world.demand.load_demand``), the
constraints against the network at simulation time 0 (``uam_planner.airspace_files.load_airspace``),
and the MWIS backend must be known and available (``uam_solvers.registry``).

On success prints the network's separation model (sphere or cylinder; nothing without
``--network``) and exits 0; else prints the first refusal, naming the flag or file, the
parameter and the value, and exits 2. ``scripts/run_fleet.sh`` runs it with the values it will
pass to the nodes.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import yaml

from uam_contract.launch_options import LAUNCH_OPTIONS
from uam_contract.params import TABLES


class PreflightError(ValueError):
    """A refused input; the message names where it came from, the field and the value."""


#: run_fleet.sh flags whose node parameter has another name than the launch argument (the
#: launch_options table names the rest: its launch argument is the parameter's name)
_FLAG_OF_PARAM = {"duration_s": "--duration", "real_time_factor": "--rtf", "departure_slot_s": "--slot-s",
                  "climb_rate_mps": "--climb-rate", "descent_rate_mps": "--descent-rate",
                  "disturbance_seed": "--seed", "default_backend": "--backend", "port": "--uss-port",
                  "auth": "--uss-auth", "auth_key": "--uss-auth-key", "auth_audience": "--uss-audience"}


def flag_of(param: str) -> str:
    """The run_fleet.sh flag that sets ``param``, or '' when none does."""
    if param in _FLAG_OF_PARAM:
        return _FLAG_OF_PARAM[param]
    return next((o.flag for o in LAUNCH_OPTIONS if o.arg == param and o.flag), "")


@dataclass
class NodeParams:
    """One node's parameters as it would start: {name: (value, where it was given)}."""

    node: str
    values: dict = field(default_factory=dict)


def _ros_value(text: str):
    """A ``-p name:=value`` value as ROS reads it: YAML (``600`` an integer, ``[a, b]`` a list,
    ``'save'`` a string); an empty value is the empty string."""
    if text == "":
        return ""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def _params_file(path: str, node: str) -> dict:
    try:
        with open(path, encoding="utf-8") as f:
            doc = yaml.safe_load(f) or {}
    except OSError as exc:
        raise PreflightError(f"{node} --params-file: {exc.strerror}: {path!r}") from None
    except yaml.YAMLError as exc:
        raise PreflightError(f"{node} --params-file {path!r}: not valid YAML ({exc})") from None
    if not isinstance(doc, dict):
        raise PreflightError(f"{path}: {doc!r} is not a mapping of node names")
    out = {}
    for key in ("/**", node, "/" + node):
        section = doc.get(key)
        if isinstance(section, dict):
            out.update(section.get("ros__parameters") or {})
    return out


def parse_args(argv: list[str]) -> tuple[dict, list[NodeParams]]:
    """(options, nodes) from the command line (see the module's docstring)."""
    opts = {"prog": "preflight", "backend": "", "network": "", "demand": "", "constraints": ""}
    nodes: list[NodeParams] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        if i + 1 >= len(argv):
            raise PreflightError(f"{arg}: needs a value")
        value = argv[i + 1]
        if arg == "--node":
            if value not in TABLES:
                raise PreflightError(f"--node: {value!r} is not one of {', '.join(TABLES)}")
            nodes.append(NodeParams(value))
        elif arg in ("--params-file", "-p") and not nodes:
            raise PreflightError(f"{arg} {value!r}: give --node first")
        elif arg == "--params-file":
            for name, v in _params_file(value, nodes[-1].node).items():
                nodes[-1].values[name] = (v, value)
        elif arg == "-p":
            name, sep, text = value.partition(":=")
            if not sep:
                raise PreflightError(f"-p {value!r}: not name:=value")
            nodes[-1].values[name] = (_ros_value(text), "-p")
        elif arg.startswith("--") and arg[2:] in opts:
            opts[arg[2:]] = value
        else:
            raise PreflightError(f"unknown argument {arg!r}")
        i += 2
    return opts, nodes


def _rules() -> dict:
    """The rules a table names (``Param.rule``), as the nodes supply them."""
    from uam_planner.objectives import objective_problem
    from uam_solvers.registry import PARAM_RULES
    return {**PARAM_RULES, "objective_name": objective_problem}


def check_params(nodes: list[NodeParams]) -> dict:
    """Every value against its node's table (and the rules it names); returns {node: {name:
    validated value}}."""
    from uam_contract.validation import with_rule

    rules = _rules()
    checked = {}
    for n in nodes:
        table = {p.name: (with_rule(p, rules[p.rule]) if p.rule else p) for p in TABLES[n.node]}
        values = {}
        for name, (value, where) in n.values.items():
            p = table.get(name)
            if p is None:
                raise PreflightError(f"{where}: {n.node} has no parameter {name!r} (value {value!r}); "
                                     f"known: {', '.join(table)}")
            flag = flag_of(name) if where == "-p" else ""
            label = f"{flag} ({n.node} parameter {name})" if flag else \
                f"{n.node} parameter {name}" + (f" ({where})" if where != "-p" else "")
            values[name] = p.validate(value, label=label, error=PreflightError)
        checked[n.node] = values
    return checked


def check_backend(name: str) -> None:
    from uam_solvers.registry import UnknownBackendError, get_backend

    try:
        ok, why = get_backend(name).available()
    except UnknownBackendError as exc:
        raise PreflightError(f"--backend: {exc}") from None
    if not ok:
        raise PreflightError(f"--backend: {name!r} is unavailable here: {why}")


def check_files(opts: dict, checked: dict):
    """Load the network, the demand file and the constraints as the nodes will; returns the
    network (None without ``--network``)."""
    network = None
    if opts["network"]:
        from uam_planner.network import load_network

        try:
            network = load_network(opts["network"])
        except (OSError, ValueError) as exc:
            raise PreflightError(f"--network: {exc}") from None
    if opts["demand"]:
        from uam_sim.world.demand import DEFAULT_WINDOW_S, load_demand

        window_s = checked.get("request_generator", {}).get("window_s", DEFAULT_WINDOW_S)
        try:
            load_demand(opts["demand"], network.aerodrome_ids if network else None, window_s)
        except (OSError, ValueError) as exc:
            raise PreflightError(f"--demand: {exc}") from None
    if opts["constraints"]:
        if network is None:
            raise PreflightError(f"--constraints {opts['constraints']!r}: needs --network (they are checked against it)")
        from uam_planner.airspace_files import load_airspace

        try:
            load_airspace(opts["constraints"], network, now_s=0.0)
        except (OSError, ValueError) as exc:
            raise PreflightError(f"--constraints: {exc}") from None
    return network


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    prog = argv[argv.index("--prog") + 1] if "--prog" in argv[:-1] else "preflight"
    try:
        opts, nodes = parse_args(argv)
        checked = check_params(nodes)
        if opts["backend"]:
            check_backend(opts["backend"])
        network = check_files(opts, checked)
    except PreflightError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    if network is not None:
        print(network.separation_model)
    return 0


if __name__ == "__main__":
    sys.exit(main())
