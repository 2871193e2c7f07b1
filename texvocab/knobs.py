"""Settings groups whose fields carry their own checks.

A settings group is a dataclass with a ``GROUP`` name (``"render"``) whose fields are
made by :func:`knob`: the default, the checks of the value's range and a one-line
description. :func:`check_group` validates a group (call it from ``__post_init__``):
each value against its type hint first (bool; int; a finite float; a ``Literal``'s
choices; a tuple of ints; ``X | None``; a nested group), then against its checks in
order. The first failure raises one :class:`~texvocab.errors.TexvocabError` naming the
setting as ``group.field`` with its value and what was expected, e.g.
``setting render.coarse_samples=0: expected >= 1``. :func:`parse_value` reads a
``--set`` string by the same type hint.

Imports nothing but :mod:`texvocab.errors`: every layer's settings may use it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from texvocab.errors import TexvocabError


@dataclass(frozen=True)
class Check:
    """``ok(value, group)`` is True for a good value; ``expected`` says what a good value
    is, in words, or is a function of the group for a bound another field sets."""

    ok: Callable[[Any, Any], bool]
    expected: str | Callable[[Any], str]

    def words(self, group) -> str:
        return self.expected(group) if callable(self.expected) else self.expected


def _num(x: float) -> str:
    """``1e-08`` as ``1e-8``, ``0.5`` as ``0.5``."""
    mantissa, e, exponent = f"{x:g}".partition("e")
    return mantissa + (f"e{int(exponent)}" if e else "")


def at_least(low: float, unit: str = "") -> Check:
    return Check(lambda v, _: v >= low, f">= {_num(low)}{unit}")


def above(low: float, unit: str = "") -> Check:
    return Check(lambda v, _: v > low, f"> {_num(low)}{unit}")


def within(
    low: float, high: float, *, open_low: bool = False, open_high: bool = False, unit: str = ""
) -> Check:
    """``low <= v <= high``, either end open."""

    def ok(v, _) -> bool:
        return (v > low if open_low else v >= low) and (v < high if open_high else v <= high)

    lo, hi = "(" if open_low else "[", ")" if open_high else "]"
    return Check(ok, f"in {lo}{_num(low)}, {_num(high)}{hi}{unit}")


def count_in(low: int, high: int) -> Check:
    """An integer ``low <= v <= high``."""
    return Check(lambda v, _: low <= v <= high, f"in {low}..{high}")


def knob(default: Any, *checks: Check, doc: str = "") -> Any:
    """A settings field: ``default`` (immutable), its ``checks`` and a ``doc`` line."""
    return dataclasses.field(default=default, metadata={"checks": checks, "doc": doc})


def one_of(choices: tuple[str, ...]) -> str:
    """``"a, b or c"``."""
    return choices[0] if len(choices) == 1 else ", ".join(choices[:-1]) + " or " + choices[-1]


@functools.cache
def type_hints(cls: type) -> dict[str, Any]:
    """The resolved type hint of each field of dataclass ``cls``."""
    return typing.get_type_hints(cls)


def _optional(hint) -> tuple[Any, bool]:
    """(the hint without ``None``, whether ``None`` is allowed)."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1:
            return args[0], len(args) < len(typing.get_args(hint))
    return hint, False


def _finite(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _kind(hint) -> tuple[Callable[[Any], bool], str]:
    """(is this value of the hint's type, what the type is in words)."""
    if typing.get_origin(hint) is Literal:
        choices = typing.get_args(hint)
        return (lambda v: isinstance(v, str) and v in choices), one_of(choices)
    if typing.get_origin(hint) is tuple:
        return (lambda v: isinstance(v, tuple) and all(type(x) is int for x in v)), "a list of view indices"
    if hint is bool:
        return (lambda v: isinstance(v, bool)), "true or false"
    if hint is int:
        return (lambda v: type(v) is int), "an integer"
    if hint is float:
        return _finite, "a finite number"
    if hint is str:
        return (lambda v: isinstance(v, str)), "a name"
    if dataclasses.is_dataclass(hint):
        example = ", ".join(f"{hint.GROUP}.{f.name}=..." for f in dataclasses.fields(hint)[:2])
        return (lambda v: isinstance(v, hint)), f"a group of settings ({example})"
    raise TypeError(f"no settings type for hint {hint!r}")


def check_group(group) -> None:
    """Raise TexvocabError naming the first field of ``group`` whose value is of the wrong
    type, else the first outside its checks (``None`` passes the checks of an optional
    field). Types come first, so a check bounding one field by another sees a number."""
    prefix, hints = type(group).GROUP, type_hints(type(group))
    prefix += "." if prefix else ""
    for f in dataclasses.fields(group):
        value = getattr(group, f.name)
        hint, optional = _optional(hints[f.name])
        is_kind, what = _kind(hint)
        if not (value is None and optional) and not is_kind(value):
            none = " or none" if optional else ""
            raise TexvocabError(f"setting {prefix}{f.name}={value!r}: expected {what}{none}")
    for f in dataclasses.fields(group):
        value = getattr(group, f.name)
        if value is None:
            continue
        for check in f.metadata.get("checks", ()):
            if not check.ok(value, group):
                none = " or none" if _optional(hints[f.name])[1] else ""
                raise TexvocabError(
                    f"setting {prefix}{f.name}={value!r}: expected {check.words(group)}{none}"
                )


def parse_value(raw: str, hint, item: str, name: str):
    """The value a ``--set`` string ``raw`` gives setting ``name`` of type ``hint``
    (``none`` for an optional one; lists of integers comma-separated); TexvocabError
    naming ``item`` when it does not read as one."""
    inner, optional = _optional(hint)
    if optional and raw.strip().lower() == "none":
        return None
    what = _kind(inner)[1] + (" or none" if optional else "")
    try:
        if inner is bool:
            if raw.lower() not in ("true", "false", "1", "0"):
                raise ValueError(raw)
            return raw.lower() in ("true", "1")
        if inner is int:
            return int(raw)
        if inner is float:
            return float(raw)
        if typing.get_origin(inner) is tuple:
            return tuple(int(v) for v in raw.split(",") if v.strip())
    except ValueError:
        raise TexvocabError(f"--set {item}: setting {name} expects {what}") from None
    if dataclasses.is_dataclass(inner):
        raise TexvocabError(f"--set {item}: {name} is {what}")
    return raw
