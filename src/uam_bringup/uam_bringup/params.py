"""Node parameters on an rclpy node: the tables of :mod:`uam_contract.params`, declared.

:func:`declare_table` declares a node's table (descriptions and ranges in the
``ParameterDescriptor``; ``read_only`` for those that cannot change), validates the start-up
values and installs one parameter callback that refuses, with a reason naming the parameter and
the value, any change to a read-only parameter, any value out of its range and rclpy's own
parameters that would break the node (:data:`uam_contract.params.FROZEN_BUILTINS`); accepted
changes are handed to the node's ``on_change``. Rules that need a library (``Param.rule``) come
from the node (``rules``), so the contract stays below the libraries.
"""

from __future__ import annotations

from typing import Any, Callable

from uam_contract.params import FROZEN_BUILTINS, Param, _bool_alias, _choices_text
from uam_contract.validation import with_rule


_with_rule = with_rule   # uam_contract.validation: one composition for the nodes and the preflight


def _declared(node, p: "Param"):
    """Declare ``p`` on ``node`` and return its validated start-up value. rclpy checks an integer
    range and every type itself, with an exception of its own (a node's main() reported it as a
    crash): those values are refused here like every other, naming the parameter and the value."""
    from rclpy.exceptions import ParameterException

    try:
        value = node.declare_parameter(p.name, p.default, _descriptor(p)).value
    except ParameterException as exc:
        given = getattr(node, "_parameter_overrides", {}).get(p.name)
        if given is not None:
            p.validate(given.value)  # raises the ValueError naming the parameter and the value
        raise ValueError(f"parameter {p.name}: {exc}") from exc
    return p.validate(value)


def declare(node, name: str, default, description: str, lo=None, hi=None, choices=None, read_only=False):
    """Declare one parameter (outside a table) and return its validated value."""
    return _declared(node, Param(name, default, description, lo, hi, tuple(choices) if choices else None, read_only))


def _descriptor(p: Param):
    from rcl_interfaces.msg import IntegerRange, ParameterDescriptor

    desc = ParameterDescriptor(description=p.text(), read_only=p.read_only,
                               dynamic_typing=isinstance(p.default, float) or _bool_alias(p))
    if isinstance(p.default, int) and not isinstance(p.default, bool) and p.lo is not None and p.hi is not None:
        desc.integer_range = [IntegerRange(from_value=int(p.lo), to_value=int(p.hi), step=0)]
    if p.choices:
        desc.additional_constraints = "one of: " + _choices_text(p.choices)
    return desc




def check_builtins(node) -> None:
    """Refuse (ValueError naming it) a start-up value of a :data:`FROZEN_BUILTINS` parameter."""
    for name, why in FROZEN_BUILTINS.items():
        if node.has_parameter(name) and node.get_parameter(name).value not in (False, None):
            raise ValueError(f"{why} (given at start-up: {node.get_parameter(name).value!r})")


def declare_table(node, table: tuple[Param, ...], on_change: Callable[[str, Any], None] | None = None,
                  rules: dict[str, Callable[[Any], str]] | None = None) -> dict:
    """Declare ``table`` on ``node``; return {name: validated value}. Installs the change callback.

    A bad start-up value raises ValueError (naming the parameter and the value) before the node
    does anything else. At run time a change is refused (the set_parameters result says why) if
    the parameter is read-only or the value fails its check; else ``on_change(name, value)``
    is called with the converted value, after every parameter of the call passed. Every
    accepted change is published on ``uam/parameter_changes`` (recorded; the summary names it).
    """
    import json

    from rcl_interfaces.msg import SetParametersResult
    from std_msgs.msg import String

    from uam_bringup import qos
    from uam_contract import names

    missing = sorted({p.rule for p in table if p.rule} - set(rules or {}))
    if missing:
        raise TypeError(f"declare_table: the table names rules {missing} that the node does not supply")
    # a named rule becomes the Param's check (an extra one beside its own, if both)
    table = tuple(_with_rule(p, (rules or {})[p.rule]) if p.rule else p for p in table)
    specs = {p.name: p for p in table}
    check_builtins(node)
    values = {p.name: _declared(node, p) for p in table}

    def on_set(params):
        accepted = []
        for prm in params:
            spec = specs.get(prm.name)
            if prm.name in FROZEN_BUILTINS:
                return SetParametersResult(successful=False, reason=FROZEN_BUILTINS[prm.name] + f" (asked: {prm.value!r})")
            if spec is None:
                continue  # rclpy's own, harmless
            if spec.read_only:
                return SetParametersResult(successful=False, reason=(
                    f"parameter {prm.name} is read-only: it is read at start-up only; restart the node "
                    f"with the new value (asked: {prm.value!r})"))
            try:
                accepted.append((prm.name, spec.validate(prm.value)))
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for name, value in accepted:
            values[name] = value
            if on_change is not None:
                on_change(name, value)
            changes.publish(String(data=json.dumps({"node": node.get_fully_qualified_name(), "parameter": name,
                                                    "value": value}, default=str)))
        return SetParametersResult(successful=True)

    changes = node.create_publisher(String, names.TOPIC_PARAMETER_CHANGES, qos.QOS_LATCHED)
    node.add_on_set_parameters_callback(on_set)
    return values


