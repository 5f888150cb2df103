"""One validation style for every input: a refusal names the field and the value.

Two tools, one message shape ``<field path>: <value> <why>``:

* :class:`Param`, the one row class of a declared option: a node parameter (the tables of
  :mod:`uam_contract.params`) and an MWIS backend option (``uam_solvers.options.Option`` builds
  a ``Param``) are the same row: name, default (whose type is the row's ``kind`` unless given),
  description, ``lo``/``hi``, ``choices``, an extra rule. :meth:`Param.validate` is the one check of
  both; the caller names the field (``parameter k`` or ``options['num_reads']``) and the error type.
* :func:`parse`, the pydantic front of the file and config inputs (experiment config, capacity
  study, demand files, the network file's schema): a pydantic model (or type) validates
  structure, types and ranges, and the first error becomes one ``ValueError`` subclass chosen by the
  caller (``ExperimentError``, ``DemandError``, ``NetworkError``) whose message is
  ``arms[2].rates: 'x' is not a finite number``, the path as a reader writes it.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Callable

__all__ = ["Param", "parse", "message", "path_text", "choices_text"]


def choices_text(choices) -> str:
    """The choices as a reader sees them: the empty choice as ''."""
    return ", ".join("''" if c == "" else str(c) for c in choices)


def _kind_of(default) -> str:
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, float):
        return "float"
    if isinstance(default, int):
        return "int"
    if isinstance(default, str):
        return "str"
    return "any"


@dataclass(frozen=True)
class Param:
    """One declared option: a node parameter or a backend option.

    ``kind`` ("bool", "int", "float", "str" or "any") is the default's type unless given (a backend
    option whose default is None names it); ``lo``/``hi`` bound numbers (inclusive), ``choices``
    lists the allowed values; ``read_only``: a node parameter set at start-up only; ``check``: an
    extra rule, value -> '' or the reason (naming the value); ``rule``: a rule that needs a
    library (e.g. the known MWIS backends), named here and supplied by the node that declares the
    table (``uam_bringup.params.declare_table``'s ``rules``); ``nullable``: None is allowed (a
    backend option: "the backend decides"); ``convert``: value -> value, raising ValueError with the
    reason (a backend option of kind "any", e.g. ``beta_range``).
    """

    name: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None
    read_only: bool = True
    check: Callable[[Any], str] | None = None
    rule: str = ""
    kind: str = ""
    nullable: bool = False
    convert: Callable[[Any], Any] | None = None

    def __post_init__(self):
        if not self.kind:
            object.__setattr__(self, "kind", _kind_of(self.default))
        if self.choices is not None:
            object.__setattr__(self, "choices", tuple(self.choices) or None)

    @classmethod
    def option(cls, name: str, kind: str, default: Any, description: str, lo=None, hi=None,
               choices=(), nullable: bool = False, validator: Callable[[Any], Any] | None = None
               ) -> "Param":
        """A backend option (``uam_solvers.options.Option``'s signature): kind given first."""
        return cls(name, default, description, lo, hi, tuple(choices) or None, read_only=False,
                   kind=kind, nullable=nullable, convert=validator)

    def validate(self, value, label: str | None = None, context: str = "",
                 error: type[Exception] = ValueError):
        """``value`` converted to the row's kind, or ``error`` naming ``label`` (by default
        ``parameter <name>``) and the value, then ``context`` (e.g. `` (backend 'sa')``)."""
        def bad(why: str) -> Exception:
            where = f"parameter {self.name}" if label is None else label
            return error(f"{where}: {value!r} {why}{context}")

        if value is None:
            if self.nullable or self.default is None:
                return None
            if self.kind == "any":
                raise bad("is not allowed (no value)")
        kind = self.kind
        if kind == "bool":
            # an integer 0 or 1 is a truth value (a backend option given as 1 was accepted)
            if not isinstance(value, bool) and not (isinstance(value, numbers.Integral) and value in (0, 1)):
                raise bad("is not true or false")
            value = bool(value)
        elif kind == "float":
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise bad("is not a finite number")
            value = float(value)
        elif kind == "int":
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise bad("is not an integer")
            value = int(value)
        elif kind == "str":
            if isinstance(value, bool) and self.choices is not None and {"off", "on"} & set(self.choices):
                # `-p rerun:=off`: ROS reads the argument as YAML, where off is the boolean false
                value = "on" if value else "off"
            elif not isinstance(value, str):
                raise bad("is not a string")
        if self.lo is not None and value < self.lo:
            raise bad(f"is below the minimum {self.lo}")
        if self.hi is not None and value > self.hi:
            raise bad(f"is above the maximum {self.hi}")
        if self.choices is not None and value not in self.choices:
            raise bad(f"is not one of {choices_text(self.choices)}")
        if self.check is not None:
            why = self.check(value)
            if why:
                raise error(f"{f'parameter {self.name}' if label is None else label}: {why}{context}")
        if self.convert is not None:
            try:
                value = self.convert(value)
            except (TypeError, ValueError) as exc:
                raise bad(str(exc)) from None
        return value

    def text(self) -> str:
        """The description with the range or the choices (docs/parameters.md)."""
        t = self.description
        if self.lo is not None or self.hi is not None:
            t += f" (range [{self.lo if self.lo is not None else '-inf'}, {self.hi if self.hi is not None else 'inf'}])"
        if self.choices:
            t += f" (one of: {choices_text(self.choices)})"
        return t

    def describe(self) -> str:
        """One line: name, kind, default, range, description (a backend's option listing)."""
        rng = ""
        if self.lo is not None or self.hi is not None:
            rng = f" in [{self.lo if self.lo is not None else '-inf'}, {self.hi if self.hi is not None else 'inf'}]"
        if self.choices:
            rng = f" one of {', '.join(map(str, self.choices))}"
        return f"{self.name} ({self.kind}{rng}, default {self.default!r}): {self.description}"


# ---- pydantic: the file and config inputs -------------------------------------------------------

def path_text(where: str, loc, tag: Callable[[tuple], str] | None = None) -> str:
    """A pydantic location as a reader writes it: ``('arms', 2, 'rates')`` -> ``arms[2].rates``,
    after ``where`` (``demand`` + ``(0, 't_s')`` -> ``demand[0].t_s``). ``tag(loc up to an index)``
    may name the item after its index (``nodes[3] (id 'W2').lat``), unless the refusal is of the
    field the tag shows (``id``)."""
    out = where
    loc = tuple(loc)
    for k, part in enumerate(loc):
        if isinstance(part, int):
            out += f"[{part}]"
            if tag is not None and k + 1 < len(loc) and loc[k + 1] != "id":
                out += tag(loc[: k + 1])
        elif "[" in str(part) or "(" in str(part) or "," in str(part):
            continue  # a union member's or function validator's tag, not a field
        else:
            out += f".{part}" if out else str(part)
    return out


def _echo(value) -> str:
    from uam_contract.ids import echo

    return echo(value)


def _fields(cls) -> dict | None:
    """{name: annotation} of a pydantic model or a dataclass, else None."""
    import dataclasses
    import typing

    import pydantic

    if isinstance(cls, type) and issubclass(cls, pydantic.BaseModel):
        return {f.alias or k: f.annotation for k, f in cls.model_fields.items()}
    if isinstance(cls, type) and dataclasses.is_dataclass(cls):
        hints = typing.get_type_hints(cls, include_extras=True)
        return {f.name: hints.get(f.name) for f in dataclasses.fields(cls)}
    return None


def _known(model, loc) -> list[str] | None:
    """The field names of the model at ``loc`` (for an unknown key), if it is a model."""
    import typing

    cur = model
    for part in loc:
        while typing.get_origin(cur) in (typing.Annotated, typing.Union):
            args = [a for a in typing.get_args(cur) if a is not type(None)]
            cur = args[0]
        fields = _fields(cur)
        if isinstance(part, int) and typing.get_origin(cur) in (list, tuple):
            cur = typing.get_args(cur)[0]
        elif fields is not None and part in fields:
            cur = fields[part]
        else:
            return None
    while typing.get_origin(cur) in (typing.Annotated, typing.Union):
        cur = [a for a in typing.get_args(cur) if a is not type(None)][0]
    fields = _fields(cur)
    return sorted(fields) if fields is not None else None


# pydantic error types whose reason quotes one value of the error's context: (template, key)
_BOUND_REASONS = {
    "literal_error": ("is not one of {}", "expected"),
    "greater_than_equal": ("is below the minimum {}", "ge"),
    "less_than_equal": ("is above the maximum {}", "le"),
    "greater_than": ("must be > {}", "gt"),
    "less_than": ("must be < {}", "lt"),
    "too_short": ("must have at least {} item(s)", "min_length"),
    "too_long": ("must have at most {} item(s)", "max_length"),
}
_REASONS = {
    "int_type": "is not an integer", "int_parsing": "is not an integer",
    "int_from_float": "is not an integer",
    "float_type": "is not a finite number", "float_parsing": "is not a finite number",
    "finite_number": "is not a finite number",
    "bool_type": "is not true or false", "bool_parsing": "is not true or false",
    "string_type": "is not a string", "list_type": "is not a list",
    "dict_type": "is not a mapping", "model_type": "is not a mapping",
    "model_attributes_type": "is not a mapping", "dataclass_type": "is not a mapping",
    "tuple_type": "is not a list",
}


def message(err: dict, where: str = "", model=None, tag=None) -> str:
    """One pydantic error (an item of ``ValidationError.errors()``) in the house style."""
    typ, ctx, value = err["type"], err.get("ctx") or {}, err.get("input")
    loc = tuple(err["loc"])
    path = path_text(where, loc, tag) or "value"
    if typ == "missing":
        return f"{path}: missing"
    if typ in ("extra_forbidden", "unexpected_keyword_argument"):
        known = _known(model, loc[:-1]) if model is not None else None
        tail = f"; known: {', '.join(known)}" if known else ""
        return f"{path}: unknown field (value {_echo(value)}{tail})"
    if typ in ("value_error", "assertion_error"):
        why = str(ctx.get("error", err["msg"]))
    elif typ in _REASONS:
        why = _REASONS[typ]
    elif typ in _BOUND_REASONS:
        template, key = _BOUND_REASONS[typ]
        why = template.format(ctx.get(key))
    else:
        why = err["msg"][:1].lower() + err["msg"][1:]
    return f"{path}: {_echo(value)} {why}"


def parse(model, data, where: str = "", error: type[Exception] = ValueError,
          tag: Callable[[tuple], str] | None = None):
    """``data`` validated by ``model`` (a pydantic model class or any type pydantic validates,
    e.g. ``list[Entry]``); the first error raised as ``error`` in the house style, naming the path
    after ``where`` (with ``tag``: :func:`path_text`) and the value."""
    import pydantic

    adapter = _adapter(model)
    try:
        return adapter.validate_python(data)
    except pydantic.ValidationError as exc:
        raise error(message(_first(exc.errors(include_url=False), model), where, model, tag)) from None


def _first(errors: list, model) -> dict:
    """The first error; a value that fits no member of a union (pydantic reports one error per
    member, each under the member's tag) becomes one error at the field, naming every member."""
    first = errors[0]
    loc = tuple(first["loc"])
    if not loc or not isinstance(loc[-1], str) or first["type"] == "missing":
        return first
    known = _known(model, loc[:-2]) if len(loc) >= 2 else None
    inner = _known(model, loc[:-1])
    if known is None or loc[-2] not in known or (inner and loc[-1] in inner):
        return first  # loc[-1] is a field, not a union member's tag
    same = [e for e in errors if tuple(e["loc"])[:-1] == loc[:-1] and len(e["loc"]) == len(loc)]
    if len(same) < 2:
        return first
    members = [_REASONS.get(e["type"], "").replace("is not ", "") or str(e["loc"][-1]) for e in same]
    return {"type": "value_error", "loc": loc[:-1], "input": first.get("input"),
            "ctx": {"error": "is not " + " or ".join(dict.fromkeys(members))}, "msg": ""}


_ADAPTERS: dict = {}


def _adapter(model):
    """One TypeAdapter per model (building one costs about a millisecond: measured, BENCHMARKS.md)."""
    import pydantic

    try:
        return _ADAPTERS[model]
    except (KeyError, TypeError):
        pass
    adapter = pydantic.TypeAdapter(model)
    try:
        _ADAPTERS[model] = adapter
    except TypeError:
        pass
    return adapter


def with_rule(p: "Param", rule) -> "Param":
    """``p`` with ``rule`` (value -> '' or the reason) checked after its own check: how a table's
    named rule (``Param.rule``) is supplied."""
    import dataclasses

    own = p.check
    if own is None:
        return dataclasses.replace(p, check=rule)
    return dataclasses.replace(p, check=lambda v: own(v) or rule(v))
