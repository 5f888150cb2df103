"""The import graph of the packages under src/: no cycle between modules, none between packages,
and no library importing a layer above it (uam_solvers < uam_planner < uam_sim < nodes and
uam_bringup). Every import counts, including those inside functions: a cycle through a lazy import
is still a cycle (it only fails later, at run time, in whichever order the modules are first used).

Parsed from the source with ``ast`` (nothing is imported), so it also covers modules that need
ROS or optional libraries."""

from __future__ import annotations

import ast
import pathlib

import networkx as nx

SRC = pathlib.Path(__file__).resolve().parents[1] / "src"
LIBRARY_LAYERS = {"uam_solvers": 0, "uam_planner": 1, "uam_sim": 2}
GLUE_LAYER = 3  # `<pkg>.nodes` subpackages and uam_bringup: ROS glue above every library
#: Cycles inside a library another branch reworks (uam_solvers: wt-solv); the test fails once
#: one of them is gone, so the entry gets removed with the merge.
PENDING_ELSEWHERE = [["uam_solvers.layers", "uam_solvers.reductions"]]


def _modules() -> dict[str, pathlib.Path]:
    """Dotted module name -> file, for every Python package directly under src/<pkg>/<pkg>/."""
    out = {}
    for pkg_dir in sorted(p for p in SRC.glob("*/*") if (p / "__init__.py").is_file()):
        for path in pkg_dir.rglob("*.py"):
            parts = list(path.relative_to(pkg_dir.parent).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _imports(name: str, path: pathlib.Path, known: set[str]) -> set[str]:
    """Project modules imported anywhere in the file (resolved to the longest known name)."""
    is_pkg = path.name == "__init__.py"
    package = name if is_pkg else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            targets.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            # `from pkg import sub` may name a submodule
            targets.update(f"{mod}.{a.name}" for a in node.names)
            targets.add(mod)
    resolved = set()
    for t in targets:
        parts = t.split(".")
        while parts and ".".join(parts) not in known:
            parts.pop()
        if parts and ".".join(parts) != name:
            resolved.add(".".join(parts))
    return resolved


def _graph() -> nx.DiGraph:
    mods = _modules()
    g = nx.DiGraph()
    g.add_nodes_from(mods)
    for name, path in mods.items():
        for target in _imports(name, path, set(mods)):
            g.add_edge(name, target)
    return g


def _unit(module: str) -> str:
    """The package a module belongs to for layering: `<pkg>.nodes` counts as its own unit."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and parts[1] == "nodes" else parts[0]


def _layer(unit: str) -> int:
    return LIBRARY_LAYERS.get(unit, GLUE_LAYER)


def _cycles(g: nx.DiGraph) -> list[list[str]]:
    return [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]


def test_the_parser_sees_the_packages_and_a_cycle_when_there_is_one():
    g = _graph()
    assert {"uam_solvers.base", "uam_planner.planning", "uam_sim.analysis"} <= set(g.nodes)
    assert g.has_edge("uam_planner.planning", "uam_solvers.base") or any(
        t.startswith("uam_solvers") for t in g.successors("uam_planner.planning"))
    g.add_edge("uam_solvers.base", "uam_planner.planning")
    assert _cycles(g)


def test_no_import_cycle_between_modules():
    cycles = _cycles(_graph())
    gone = [c for c in PENDING_ELSEWHERE if c not in cycles]
    assert not gone, f"no longer cycles, remove them from PENDING_ELSEWHERE: {gone}"
    cycles = [c for c in cycles if c not in PENDING_ELSEWHERE]
    assert not cycles, "import cycles between modules:\n" + "\n".join(
        " <-> ".join(c) for c in cycles)


def test_no_import_cycle_between_packages_and_no_library_imports_a_layer_above():
    g = _graph()
    units = nx.DiGraph()
    upward = []
    for a, b in g.edges:
        ua, ub = _unit(a), _unit(b)
        if ua != ub:
            units.add_edge(ua, ub)
            if _layer(ub) > _layer(ua):
                upward.append(f"{a} -> {b}")
    assert not upward, "library modules importing a layer above them:\n" + "\n".join(sorted(upward))
    cycles = _cycles(units)
    assert not cycles, f"import cycles between packages: {cycles}"
