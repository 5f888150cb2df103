"""Priority by grant: which priority classes each operator may ask for.

A request's ``priority`` (0..255, ASTM F3548 style) is the operator's claim. Under the
``priority`` objective it decides who flies, so it is taken only up to the class the operator is
granted: a grants file, read once at start (the planner's ``priority_grants``)::

    default: 0            # the highest class an operator not listed may ask for
    operators:
      medevac: 255        # e.g. a medical operator
      generator: 1

A request above its operator's grant is refused, naming the field, the value and the grant
(:meth:`PriorityGrants.check`); the planning library applies it in ``Planner.validate``, so the
node, the in-process runner, demand files and the request generator follow the same grants.
Without a grants file every class is taken (the paper's runs, where every request has class 0).

rclpy-free.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

MAX_CLASS = 255


def read_yaml(path, what: str):
    """The YAML document of a configuration file; ValueError naming ``what`` and the file."""
    import yaml

    p = Path(path)
    try:
        return yaml.safe_load(p.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"{what}: {p}: {exc}") from None


def _class(value, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_CLASS:
        raise ValueError(f"{where}: {value!r} is not a priority class 0..{MAX_CLASS}")
    return int(value)


@dataclass(frozen=True)
class PriorityGrants:
    """The highest priority class each operator may ask for (``default`` for the others)."""

    default: int = 0
    operators: dict = field(default_factory=dict)

    def grant(self, operator_id: str) -> int:
        return int(self.operators.get(operator_id, self.default))

    def check(self, operator_id: str, priority: int) -> str | None:
        """Why a request of ``operator_id`` with ``priority`` is above its grant, or None."""
        g = self.grant(operator_id)
        if int(priority) > g:
            return (f"priority: {int(priority)} is above operator {operator_id!r}'s grant {g} "
                    "(priority_grants: the classes each operator may ask for)")
        return None

    @classmethod
    def from_mapping(cls, doc, where: str = "priority_grants") -> "PriorityGrants":
        if not isinstance(doc, dict):
            raise ValueError(f"{where}: not a mapping with 'default' and 'operators'")
        unknown = sorted(set(doc) - {"default", "operators"})
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {', '.join(map(str, unknown))} (default, operators)")
        ops = doc.get("operators") or {}
        if not isinstance(ops, dict):
            raise ValueError(f"{where}.operators: {ops!r} is not a mapping of operator id to class")
        return cls(_class(doc.get("default", 0), f"{where}.default"),
                   {str(k): _class(v, f"{where}.operators.{k}") for k, v in ops.items()})

    @classmethod
    def load(cls, path) -> "PriorityGrants":
        """Read a grants file (YAML); ValueError naming the file and the entry."""
        return cls.from_mapping(read_yaml(path, "priority_grants"), f"priority_grants: {Path(path)}")

    def as_yaml(self) -> str:
        lines = ["# priority classes each operator may ask for (uam_planner.grants)", f"default: {self.default}",
                 "operators:" + ("" if self.operators else " {}")]
        lines += [f"  {k}: {v}" for k, v in sorted(self.operators.items())]
        return "\n".join(lines) + "\n"


__all__ = ["MAX_CLASS", "PriorityGrants"]
