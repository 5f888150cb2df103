"""The import layering of the packages: no module imports a layer above its own, no cycles, and
every package declares (package.xml) what it imports.

Layers, lowest first (docs/architecture.md): uam_contract (names, QoS specs, wire limits, stamps,
parameter tables; plain Python), the libraries uam_solvers < uam_planner < uam_sim, then
uam_bringup (the rclpy glue: no library), then every library's ``nodes`` subpackage. Every
import counts, at module level or inside a function (a lazy import is still a dependency). Read
from the source with ``ast``, nothing is imported.
"""

from __future__ import annotations

import ast
import functools
import pathlib
import re
import xml.etree.ElementTree as ET

import networkx as nx

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("uam_contract", "uam_solvers", "uam_planner", "uam_sim", "uam_bringup")
LIBRARY_RANK = {"uam_contract": 0, "uam_solvers": 1, "uam_planner": 2, "uam_sim": 3, "uam_bringup": 4}
NODES_RANK = 5

# Exceptions allowed (none): anything listed here that no longer holds fails the test too, so the
# lists can only shrink. Issue 9 removed uam_solvers.instances -> uam_sim.audit.analysis and
# recording <-> analysis; issue 11 removed layers <-> reductions and base <-> options.
KNOWN_UPWARD_IMPORTS: set = set()
KNOWN_CYCLES: set = set()


@functools.lru_cache(maxsize=None)
def _parse(path: pathlib.Path) -> ast.Module:
    """The syntax tree of one source file, parsed once per test run (the tests only read it)."""
    return ast.parse(path.read_text(), str(path))


def _modules() -> dict[str, pathlib.Path]:
    mods = {}
    for pkg in PACKAGES:
        base = ROOT / "src" / pkg
        for path in (base / pkg).rglob("*.py"):
            parts = list(path.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = path
    return mods


def _rank(module: str) -> int:
    parts = module.split(".")
    return NODES_RANK if "nodes" in parts[1:2] else LIBRARY_RANK[parts[0]]


# The rooms of uam_sim, lowest first (src/uam_sim/README.md): a module imports only from its own
# room or a lower one. Rooms of one rank (the views and the F3548 interface) never import each
# other. The top level holds the package's facade and the ``python -m uam_sim.<command>`` modules,
# above every room; ``recording/__main__`` is the recording room's command, at that level too.
SIM_ROOMS = {"world": 0, "recording": 1, "audit": 2, "views": 3, "f3548": 3, "runner": 4, "reports": 5,
             "studies": 6}
SIM_COMMANDS_RANK = 7


def _sim_room(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "uam_sim" or parts[1:2] == ["nodes"] or len(parts) < 2:
        return None
    if parts[-1] == "__main__" or len(parts) == 2 and parts[1] not in SIM_ROOMS:
        return "commands"
    return parts[1]


def _sim_rank(room: str) -> int:
    return SIM_COMMANDS_RANK if room == "commands" else SIM_ROOMS[room]


def _imports(module: str, path: pathlib.Path, known: set[str]) -> set[str]:
    """Project modules that ``module`` imports (resolved to the longest known module name)."""
    tree = _parse(path)
    is_pkg = path.name == "__init__.py"
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_pkg else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names.add(target)
            names.update(f"{target}.{a.name}" for a in node.names)
    out = set()
    for name in names:
        parts = name.split(".")
        while parts and ".".join(parts) not in known:
            parts.pop()
        if parts and ".".join(parts) != module:
            out.add(".".join(parts))
    return out


def _graph() -> nx.DiGraph:
    """The module import graph; a copy of the one built once, so a test may add edges to it."""
    return _build_graph().copy()


@functools.lru_cache(maxsize=None)
def _build_graph() -> nx.DiGraph:
    mods = _modules()
    g = nx.DiGraph()
    g.add_nodes_from(mods)
    for mod, path in mods.items():
        for dep in _imports(mod, path, set(mods)):
            # a package's __init__ importing its own submodules is not a dependency cycle
            if not mod.startswith(dep + "."):
                g.add_edge(mod, dep)
    return g


def test_the_layering_sees_the_packages():
    g = _graph()
    assert {"uam_contract.names", "uam_planner.planning", "uam_planner.nodes.planner_node"} <= set(g)
    assert g.has_edge("uam_planner.nodes.planner_node", "uam_bringup.runtime")
    assert g.has_edge("uam_planner.nodes.conversions", "uam_planner.planning")


def test_no_module_imports_a_layer_above_its_own():
    g = _graph()
    upward = {(a, b) for a, b in g.edges if _rank(b) > _rank(a)}
    assert upward - KNOWN_UPWARD_IMPORTS == set(), sorted(upward - KNOWN_UPWARD_IMPORTS)
    assert KNOWN_UPWARD_IMPORTS - upward == set(), "fixed: remove from KNOWN_UPWARD_IMPORTS"


def test_uam_sim_rooms_import_only_their_own_or_lower_rooms():
    g = _graph()
    rooms = {_sim_room(m) for m in g} - {None}
    assert set(SIM_ROOMS) <= rooms and "commands" in rooms, sorted(rooms - {None})
    mods = _modules()
    flat = [m for m in g if _sim_room(m) == "commands" and not m.endswith("__main__") and m != "uam_sim"
            and not _main_only(m, mods)]
    assert flat == [], f"a top-level uam_sim module that is not a command: {flat}"
    bad = []
    for a, b in g.edges:
        ra, rb = _sim_room(a), _sim_room(b)
        if ra is None or rb is None or ra == rb:
            continue
        if _sim_rank(rb) > _sim_rank(ra) or (_sim_rank(rb) == _sim_rank(ra) and ra != rb):
            bad.append((a, b))
    assert bad == [], sorted(bad)


def _main_only(module: str, mods: dict | None = None) -> bool:
    """True when a top-level module only imports a room's ``main`` and runs it (a command)."""
    path = (mods or _modules())[module]
    tree = _parse(path)
    imports = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    return all(isinstance(n, ast.Import) or [a.name for a in n.names] == ["main"] for n in imports) and \
        len([n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))]) == 0


def test_an_upward_room_import_is_seen():
    assert _sim_rank(_sim_room("uam_sim.audit.analysis")) > _sim_rank(_sim_room("uam_sim.recording.cdr"))
    assert _sim_rank(_sim_room("uam_sim.analysis")) > _sim_rank(_sim_room("uam_sim.studies.montecarlo"))
    assert _sim_room("uam_sim.recording.__main__") == "commands"
    assert _sim_room("uam_sim.nodes.simulator_node") is None
    assert _main_only("uam_sim.analysis") and not _main_only("uam_sim.audit.analysis")


def test_library_and_contract_modules_never_import_rclpy_at_import_time():
    """They work without ROS (the analysis of a recording, the experiment runner); a function may
    import rclpy.serialization lazily to turn message objects into CDR."""
    offenders = []
    for mod, path in _modules().items():
        if _rank(mod) == NODES_RANK or mod.startswith("uam_bringup."):
            continue  # glue: allowed
        tree = _parse(path)
        for node in tree.body:
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            if any(n == "rclpy" or n.startswith("rclpy.") for n in names):
                offenders.append(mod)
    assert offenders == []


def test_no_import_cycles():
    g = _graph()
    cycles = {frozenset(c) for c in nx.strongly_connected_components(g) if len(c) > 1}
    assert cycles - KNOWN_CYCLES == set(), sorted(map(sorted, cycles - KNOWN_CYCLES))
    assert KNOWN_CYCLES - cycles == set(), "fixed: remove from KNOWN_CYCLES"


def _unit(module: str) -> str:
    """The package of a module, with each ``<pkg>.nodes`` subpackage a unit of its own."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[1:2] == ["nodes"] else parts[0]


def test_no_import_cycles_between_packages():
    """uam_contract, the libraries, uam_bringup and the nodes subpackages form a DAG."""
    g = _graph()
    units = nx.DiGraph((_unit(a), _unit(b)) for a, b in g.edges if _unit(a) != _unit(b))
    assert "uam_sim" in units and "uam_sim.nodes" in units
    cycles = [sorted(c) for c in nx.strongly_connected_components(units) if len(c) > 1]
    assert cycles == [], cycles


def test_a_cycle_or_an_upward_import_is_seen():
    g = _graph()
    assert _rank("uam_sim.audit.analysis") > _rank("uam_solvers.base")  # such an edge would be upward
    assert _rank("uam_bringup.params") > _rank("uam_sim.audit.analysis") > _rank("uam_contract.names")
    g.add_edge("uam_solvers.base", "uam_planner.planning")
    assert any(len(c) > 1 and "uam_solvers.base" in c for c in nx.strongly_connected_components(g))


def _package_graph() -> nx.DiGraph:
    """Package -> package it imports (a library's nodes subpackage counts as its package: they
    ship together, so the package.xml of the library must declare what its nodes import)."""
    g = _graph()
    return nx.DiGraph((a.split(".")[0], b.split(".")[0]) for a, b in g.edges if a.split(".")[0] != b.split(".")[0])


def _declared(pkg: str) -> set[str]:
    root = ET.parse(ROOT / "src" / pkg / "package.xml").getroot()
    return {e.text.strip() for e in root if e.tag.endswith("depend") and e.text}


def test_packages_form_one_order_and_declare_what_they_import():
    """Issue 19: the package level, not only the modules. uam_bringup imported the libraries and
    their nodes imported uam_bringup (a cycle colcon could not be told about)."""
    pg = _package_graph()
    assert nx.is_directed_acyclic_graph(pg), [sorted(c) for c in nx.simple_cycles(pg)]
    assert "uam_contract" not in pg or not set(pg.successors("uam_contract"))
    assert not set(pg.successors("uam_bringup")) - {"uam_contract"}, sorted(pg.successors("uam_bringup"))
    for pkg in PACKAGES:
        if pkg not in pg:
            continue
        undeclared = set(pg.successors(pkg)) - _declared(pkg)
        assert not undeclared, f"src/{pkg}/package.xml does not declare {sorted(undeclared)}"


def test_libraries_take_topic_names_from_the_contract():
    """No "/uam/..." or "uam/..." string literal outside uam_contract (tests aside)."""
    literal = re.compile(r"""["']/?uam/""")
    offenders = []
    for pkg in PACKAGES:
        for path in (ROOT / "src" / pkg / pkg).rglob("*.py"):
            if pkg == "uam_contract":
                continue
            for n, line in enumerate(path.read_text().splitlines(), 1):
                if literal.search(line):
                    offenders.append(f"{path.relative_to(ROOT)}:{n}")
    for path in (ROOT / "src" / "uam_bringup" / "launch").glob("*.py"):
        offenders += [f"{path.relative_to(ROOT)}:{n}" for n, line in enumerate(path.read_text().splitlines(), 1)
                      if literal.search(line)]
    assert offenders == []


def test_the_load_factor_scales_and_refuses_nonsense(monkeypatch):
    from load_factor import load_factor, slack

    monkeypatch.delenv("UAM_TEST_LOAD_FACTOR", raising=False)
    assert slack(20) == 20
    monkeypatch.setenv("UAM_TEST_LOAD_FACTOR", "3")
    assert slack(20) == 60
    for bad in ("0.5", "fast"):
        monkeypatch.setenv("UAM_TEST_LOAD_FACTOR", bad)
        try:
            load_factor()
        except ValueError as exc:
            assert "UAM_TEST_LOAD_FACTOR" in str(exc) and bad in str(exc)
        else:
            raise AssertionError(f"{bad!r} was accepted")


#: functions a reader can hold: at most this many over 80 lines, each with its reason in a
#: comment just above it (``# long (over 80 lines): ...``)
MAX_LONG_FUNCTIONS = 5


def _long_functions(root: pathlib.Path) -> list:
    """(path, name, lines, reason or None) of every function over 80 lines outside the tests."""
    out = []
    for path in sorted(root.glob("src/*/**/*.py")):
        if "/test/" in str(path):
            continue
        text = path.read_text()
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and node.end_lineno - node.lineno + 1 > 80:
                first = min([d.lineno for d in node.decorator_list] + [node.lineno]) - 1
                above = []
                for line in reversed(lines[:first]):
                    if not line.strip().startswith("#"):
                        break
                    above.insert(0, line.strip())
                reason = " ".join(above) if any(a.startswith("# long (over 80 lines)") for a in above) else None
                out.append((str(path.relative_to(root)), node.name, node.end_lineno - node.lineno + 1, reason))
    return out


def test_at_most_five_long_functions_each_with_its_reason():
    long = _long_functions(ROOT)
    assert len(long) <= MAX_LONG_FUNCTIONS, [(p, n, k) for p, n, k, _ in long]
    assert all(reason for *_, reason in long), [(p, n, k) for p, n, k, r in long if not r]


def test_a_long_function_without_its_reason_is_seen(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(85))
    pkg = tmp_path / "src" / "pkg" / "pkg"
    pkg.mkdir(parents=True)
    (pkg / "m.py").write_text(f"def f():\n{body}\n\n\n# long (over 80 lines): a table\ndef g():\n{body}\n")
    got = {n: r for _p, n, _k, r in _long_functions(tmp_path)}
    assert got["f"] is None and got["g"].startswith("# long (over 80 lines)")
