"""Declared backend options (in the style of dimod's ``Sampler.parameters``) and checks of the
solve arguments every backend shares.

Each backend lists its options as :class:`Option` rows in ``options_spec`` (name, kind,
default, range or choices, description; the row class is :class:`uam_contract.validation.Param`,
the one of the node parameters too); :func:`parse_options` checks a caller's mapping
against it and returns every option with defaults filled in. An unknown name or a malformed
value raises :class:`~uam_solvers.base.MwisInputError` naming ``options['key']``, the value and
the backend, for every backend and before any solve starts (never a silent fallback).
"""
from __future__ import annotations

import math
import numbers
from typing import Any, Mapping

from uam_contract.validation import Param

from .errors import MwisInputError

__all__ = ["Option", "parse_options", "check_time_limit", "check_seed", "MAX_TIME_LIMIT_S"]

#: The largest time limit the library accepts (one day); callers such as the solver node bound
#: it further. Larger values are nearly always unit mistakes (ms for s) and overflow timers.
MAX_TIME_LIMIT_S = 86_400.0


#: A backend option is a row of the one table type of node parameters and backend options,
#: :class:`uam_contract.validation.Param` (one validator): ``Option(name, kind, default,
#: description, lo=, hi=, choices=, nullable=, validator=)`` builds it; ``validator`` becomes its
#: ``convert`` (``f(value) -> value`` raising ValueError with the reason).
Option = Param.option


def parse_options(backend: str, spec: Mapping[str, Param], options: Mapping[str, Any] | None
                  ) -> dict:
    """Every declared option of ``spec``: the caller's value checked, else the default.

    Raises MwisInputError for a non-mapping, an unknown key (listing the known ones) or a
    malformed value.
    """
    if options is None:
        options = {}
    if not isinstance(options, Mapping):
        raise MwisInputError(f"options: {options!r} is not a mapping of option name to value")
    # the same (backend, spec, options) gives the same checked dict: cached, because one solve
    # of `auto` checks its ~20 options three times (its pipeline, itself, its KaMIS call):
    # 0.1-0.2 ms of a 0.5-1 ms solve on 50-250 vertex graphs. The key holds each
    # value's type, so True is never taken for 1, and the spec itself, so a new spec misses.
    try:
        key = (backend, id(spec), tuple((k, type(v), v) for k, v in options.items()))
        hit = _PARSED.get(key)
    except TypeError:  # an unhashable value: checked as usual, not cached
        key, hit = None, None
    if hit is not None and hit[0] is spec:
        return dict(hit[1])
    out = _parse_options(backend, spec, options)
    if key is not None:
        if len(_PARSED) >= _PARSED_MAX:
            _PARSED.clear()
        _PARSED[key] = (spec, dict(out))
    return out


#: parse_options' cache: key -> (spec, checked options)
_PARSED: dict = {}
_PARSED_MAX = 512


def _parse_options(backend: str, spec: Mapping[str, Param], options: Mapping[str, Any]) -> dict:
    unknown = [k for k in options if k not in spec]
    if unknown:
        known = ", ".join(sorted(spec)) or "none"
        raise MwisInputError(
            f"options[{unknown[0]!r}]: unknown option for backend {backend!r} "
            f"(value {options[unknown[0]]!r}; known options: {known})")
    out = {}
    for name, opt in spec.items():
        out[name] = (opt.validate(options[name], label=f"options[{name!r}]", context=f" (backend {backend!r})",
                                  error=MwisInputError)
                     if name in options else opt.default)
    return out


def check_time_limit(value: Any, field_name: str = "time_limit_s",
                     max_s: float = MAX_TIME_LIMIT_S) -> float:
    """A time limit in seconds as float: a real number, finite, > 0 and <= ``max_s``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise MwisInputError(f"{field_name}: {value!r} is not a number of seconds")
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise MwisInputError(f"{field_name}: {value!r} must be a finite number of seconds > 0")
    if v > max_s:
        raise MwisInputError(f"{field_name}: {value!r} s exceeds the maximum {max_s:g} s")
    return v


def check_seed(value: Any, field_name: str = "seed") -> int:
    """A seed as int (any integer; backends reduce it modulo their generator's range)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise MwisInputError(f"{field_name}: {value!r} is not an integer")
    return int(value)
