"""Model parameters declared once, on the model's dataclass.

Each kinematic model names its parameters with ``param(default, bounds)``: the name carries the
unit (``wheel_radius_m``), the default is the model's, and ``bounds`` says which values are
allowed. ``check_params`` (every model's ``__post_init__``) and the scenario schema
(:mod:`agvsim.scenario_schema`, which derives the typed ``params`` block of each model from
these fields) read the same declaration, so a bound is written in one place.
"""

from __future__ import annotations

import functools
import math
import typing
from dataclasses import Field, dataclass, field, fields
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Bounds:
    """The allowed values of a numeric parameter: finite, above ``gt`` and below ``lt`` (both
    exclusive; None: no bound). ``lt_text`` says how the upper bound reads (e.g. "pi/2 rad
    (90 deg)")."""

    gt: float | None = 0.0
    lt: float | None = None
    lt_text: str = ""

    def describe(self) -> str:
        """What is allowed, in words: "a positive number below pi/2 rad (90 deg)"."""
        text = "a positive number" if self.gt == 0.0 else "a finite number"
        if self.gt not in (None, 0.0):
            text += f" above {self.gt:g}"
        if self.lt is not None:
            text += f" below {self.lt_text or f'{self.lt:g}'}"
        return text

    def holds(self, value: Any) -> bool:
        """True when ``value`` (a number or an array of them) is within the bounds."""
        v = np.asarray(value, dtype=np.float64)
        ok = bool(np.all(np.isfinite(v)))
        if ok and self.gt is not None:
            ok = bool(np.all(v > self.gt))
        if ok and self.lt is not None:
            ok = bool(np.all(v < self.lt))
        return ok


POSITIVE = Bounds()
HALF_TURN = Bounds(lt=math.pi / 2, lt_text="pi/2 rad (90 deg)")  # a steering angle limit


def param(default: Any, bounds: Bounds | None = POSITIVE, doc: str = "") -> Any:
    """A model parameter: its default, the values allowed (None for a choice of texts, which
    the field's ``Literal`` type lists) and a one-line description."""
    return field(default=default, metadata={"bounds": bounds, "doc": doc})


def bounds_of(f: Field) -> Bounds | None:
    """The bounds a parameter field declares (None: not a bounded number)."""
    return f.metadata.get("bounds")


@functools.cache
def choices_of(cls: type) -> dict[str, tuple[str, ...]]:
    """Parameter name -> allowed texts, for the fields of ``cls`` typed ``Literal[...]``."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in fields(cls):
        if typing.get_origin(hints[f.name]) is typing.Literal:
            out[f.name] = tuple(str(a) for a in typing.get_args(hints[f.name]))
    return out


def check_params(model: Any) -> None:
    """Raise ValueError naming the parameter, its value and what is allowed, for the first
    parameter of ``model`` (a kinematic dataclass) out of its declared bounds or choices."""
    name = type(model).__name__
    cls: type = type(model)
    choices = choices_of(cls)
    for f in fields(model):
        value = getattr(model, f.name)
        bounds = bounds_of(f)
        if bounds is not None and not bounds.holds(value):
            raise ValueError(f"{name}.{f.name} must be {bounds.describe()}, got {value!r}")
        if f.name in choices and value not in choices[f.name]:
            allowed = " or ".join(repr(c) for c in choices[f.name])
            raise ValueError(f"{name}.{f.name} must be {allowed}, got {value!r}")
