"""Declared backend options (in the style of dimod's ``Sampler.parameters``) and checks of the
solve arguments every backend shares.

Each backend lists its options as :class:`Option` objects in ``options_spec`` (name, kind,
default, range or choices, description); :func:`parse_options` checks a caller's mapping
against it and returns every option with defaults filled in. An unknown name or a malformed
value raises :class:`~uam_solvers.base.MwisInputError` naming ``options['key']``, the value and
the backend, for every backend and before any solve starts (never a silent fallback).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from .errors import MwisInputError

__all__ = ["Option", "parse_options", "check_time_limit", "check_seed", "MAX_TIME_LIMIT_S"]

#: The largest time limit the library accepts (one day); callers such as the solver node bound
#: it further. Larger values are nearly always unit mistakes (ms for s) and overflow timers.
MAX_TIME_LIMIT_S = 86_400.0


@dataclass(frozen=True)
class Option:
    """One declared backend option.

    kind: "int", "float", "bool", "str" or "any" (then ``validator`` does the checking).
    lo, hi: inclusive numeric range (None: unbounded). choices: allowed values (str options).
    nullable: None is allowed (and means "the backend decides", described in ``description``).
    validator: optional ``f(value) -> value`` raising ValueError with a reason for "any" kinds.
    """

    name: str
    kind: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple = ()
    nullable: bool = False
    validator: Callable[[Any], Any] | None = field(default=None, compare=False)

    def check(self, value: Any, backend: str) -> Any:
        """``value`` converted to the option's kind, or MwisInputError naming option and value."""
        def bad(why: str) -> MwisInputError:
            return MwisInputError(f"options[{self.name!r}]: {value!r} {why} (backend {backend!r})")

        if value is None:
            if self.nullable or self.default is None:
                return None
            raise bad("is not allowed (no value)")
        if self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise bad("is not an integer")
            value = int(value)
        elif self.kind == "float":
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise bad("is not a number")
            value = float(value)
            if not math.isfinite(value):
                raise bad("is not finite")
        elif self.kind == "bool":
            if not isinstance(value, (bool,)) and not (isinstance(value, numbers.Integral)
                                                        and value in (0, 1)):
                raise bad("is not true or false")
            value = bool(value)
        elif self.kind == "str":
            if not isinstance(value, str):
                raise bad("is not a string")
        if self.lo is not None and value < self.lo:
            raise bad(f"is below the minimum {self.lo!r}")
        if self.hi is not None and value > self.hi:
            raise bad(f"is above the maximum {self.hi!r}")
        if self.choices and value not in self.choices:
            raise bad(f"is not one of {', '.join(map(repr, self.choices))}")
        if self.validator is not None:
            try:
                value = self.validator(value)
            except (TypeError, ValueError) as exc:
                raise bad(str(exc)) from None
        return value

    def describe(self) -> str:
        """One line: name, kind, default, range, description."""
        rng = ""
        if self.lo is not None or self.hi is not None:
            rng = f" in [{self.lo if self.lo is not None else '-inf'}, {self.hi if self.hi is not None else 'inf'}]"
        if self.choices:
            rng = f" one of {', '.join(map(str, self.choices))}"
        return f"{self.name} ({self.kind}{rng}, default {self.default!r}): {self.description}"


def parse_options(backend: str, spec: Mapping[str, Option], options: Mapping[str, Any] | None
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
    # 0.1-0.2 ms of a 0.5-1 ms solve on 50-250 vertex graphs (issue 20). The key holds each
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


def _parse_options(backend: str, spec: Mapping[str, Option], options: Mapping[str, Any]) -> dict:
    unknown = [k for k in options if k not in spec]
    if unknown:
        known = ", ".join(sorted(spec)) or "none"
        raise MwisInputError(
            f"options[{unknown[0]!r}]: unknown option for backend {backend!r} "
            f"(value {options[unknown[0]]!r}; known options: {known})")
    out = {}
    for name, opt in spec.items():
        out[name] = opt.check(options[name], backend) if name in options else opt.default
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
