"""Declaring and validating node parameters (shared by the nodes of every package; uam_solvers is
the package the others depend on): a description on each, a range where one applies.

`declare(node, name, default, description, lo=None, hi=None, choices=None)` declares the
parameter and returns its validated value. Numbers given as integers where a float is expected
(``-p duration_s:=600``) are accepted: float parameters are declared with dynamic typing and
converted here. A bad value raises ValueError naming the parameter and the value, before the node
does anything else.
"""

from __future__ import annotations

import math

from rcl_interfaces.msg import ParameterDescriptor


def declare(node, name: str, default, description: str, lo=None, hi=None, choices=None):
    is_float = isinstance(default, float)
    text = description
    if lo is not None or hi is not None:
        text += f" (range [{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}])"
    if choices:
        text += f" (one of: {', '.join(map(str, choices))})"
    desc = ParameterDescriptor(description=text, dynamic_typing=is_float)
    value = node.declare_parameter(name, default, desc).value
    return check(name, value, default, lo, hi, choices)


def check(name: str, value, default, lo=None, hi=None, choices=None):
    """Validate ``value`` of parameter ``name`` against the default's type, a range and choices."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"parameter {name}: {value!r} is not true or false")
    elif isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"parameter {name}: {value!r} is not a finite number")
        value = float(value)
    elif isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"parameter {name}: {value!r} is not an integer")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise ValueError(f"parameter {name}: {value!r} is not a string")
    if lo is not None and value < lo:
        raise ValueError(f"parameter {name}: {value!r} is below the minimum {lo}")
    if hi is not None and value > hi:
        raise ValueError(f"parameter {name}: {value!r} is above the maximum {hi}")
    if choices is not None and value not in choices:
        raise ValueError(f"parameter {name}: {value!r} is not one of {', '.join(map(str, choices))}")
    return value
