"""Declared filter parameters: default, type, range and choices, checked before any work.

A filter's ``FilterSpec.params`` maps each parameter name to its default or to a :class:`Param`.
A plain default declares its own type; a :class:`Param` adds a range, choices or a wider type.
The harness checks every ``--param``, ``--grid`` value and preset against these declarations when
it plans a run, so a bad value is a one-line error before anything renders.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: types a parameter may declare
TYPES = ("int", "float", "bool", "str", "list", "any")


def _type_of(value: Any) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "str"
    if isinstance(value, (list, tuple)):
        return "list"
    return "any"


@dataclass(frozen=True)
class Param:
    """Declaration of one filter parameter.

    Parameters
    ----------
    default : any
        The value used when the user sets none.
    type : {"int", "float", "bool", "str", "list", "any"}, optional
        What values are accepted; by default the type of ``default`` (``any`` for ``None``).
        ``float`` accepts ints (widened) and ``inf``; ``int`` accepts only integers.
    min, max : float, optional
        Inclusive bounds of a number (or of every element of a ``list``).
    min_exclusive : bool
        Make ``min`` exclusive (``> min``), e.g. for a sigma that must be positive.
    choices : tuple, optional
        The only accepted values.
    nullable : bool
        Also accept ``None`` (true when the default is ``None``).
    doc : str
        One line shown by ``denoise-bench plugins``.
    """

    default: Any
    type: str | None = None
    min: float | None = None
    max: float | None = None
    min_exclusive: bool = False
    choices: tuple | None = None
    nullable: bool = False
    doc: str = ""

    def __post_init__(self):
        kind = self.type or _type_of(self.default)
        if kind not in TYPES:
            raise ValueError(f"Param: type must be one of {TYPES}, got {kind!r}")
        object.__setattr__(self, "type", kind)
        if self.choices is not None:
            object.__setattr__(self, "choices", tuple(self.choices))
        object.__setattr__(self, "nullable", self.nullable or self.default is None)

    def describe(self) -> str:
        """What the parameter accepts, e.g. ``int in [1, 10]`` or ``one of ('a', 'b')``."""
        if self.choices is not None:
            text = f"one of {self.choices}"
        else:
            text = self.type
            if self.min is not None or self.max is not None:
                lo = "-inf" if self.min is None else f"{self.min:g}"
                hi = "inf" if self.max is None else f"{self.max:g}"
                text += f" in {'(' if self.min_exclusive else '['}{lo}, {hi}]"
        return text + (" or null" if self.nullable and self.type != "any" else "")

    def check(self, value: Any, owner: str = "parameter") -> Any:
        """Return ``value`` (ints widened for a float) or raise a one-line ``ValueError``."""
        if value is None and self.nullable:
            return None
        ok, value = self._coerce(value)
        if ok and self.choices is not None:
            ok = value in self.choices
        if ok and (self.min is not None or self.max is not None):
            numbers = value if self.type == "list" else [value]
            ok = all(self._in_range(v) for v in numbers)
        if not ok:
            raise ValueError(f"{owner} must be {self.describe()}, got {value!r}")
        return value

    def _coerce(self, value: Any) -> tuple[bool, Any]:
        kind = self.type
        if kind == "any":
            return True, value
        if kind == "bool":
            return isinstance(value, bool), value
        if kind == "int":
            return isinstance(value, int) and not isinstance(value, bool), value
        if kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                return False, value
            value = float(value)
            return not math.isnan(value), value
        if kind == "str":
            return isinstance(value, str), value
        if kind == "list":
            if not isinstance(value, (list, tuple)):
                return False, value
            if self.min is not None or self.max is not None:
                numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
                return numeric, value
            return True, value
        return False, value

    def _in_range(self, v) -> bool:
        if not isinstance(v, (int, float)) or isinstance(v, bool) or math.isnan(v):
            return False
        above = self.min is None or (v > self.min if self.min_exclusive else v >= self.min)
        return above and (self.max is None or v <= self.max)


def param_table(owner: str, params: Mapping[str, Any] | None) -> dict[str, Param]:
    """Every parameter as a :class:`Param` (plain defaults become declarations of their type).

    Raises ``ValueError`` when a declared default does not satisfy its own declaration.
    """
    table = {}
    for name, value in (params or {}).items():
        spec = value if isinstance(value, Param) else Param(value)
        spec.check(spec.default, owner=f"{owner}: default of parameter {name!r}")
        table[str(name)] = spec
    return table
