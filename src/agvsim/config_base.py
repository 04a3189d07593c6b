"""The one base class of every validated configuration block (scenario, behaviours, dynamics,
fleet, master).

``StrictConfig`` refuses what no block may hold: unknown keys (the loader turns them into
"did you mean ...?"), NaN and inf, any float of magnitude above ``MAX_MAGNITUDE`` (1e12: its
square stays finite and float32 holds it) and unbounded text. A block validated once at the
edge is frozen: the core receives plain typed values, never a dict to check again
(``construct`` hands a config's fields to a core class by name).
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, field_validator

from agvsim.scenario_limits import MAX_MAGNITUDE, too_large

T = TypeVar("T")
TEXT_MAX_CHARS = 4096  # any text field (a path at most); longer text says so in its Field


class StrictConfig(BaseModel):
    """A frozen configuration block: unknown keys, NaN / inf, huge numbers and long text are
    refused with a message naming the value and what is allowed."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, allow_inf_nan=False, str_max_length=TEXT_MAX_CHARS
    )

    @field_validator("*")
    @classmethod
    def _not_huge(cls, value: Any) -> Any:
        if (bad := too_large(value)) is not None:
            item = f"{bad!r} is " if isinstance(value, list | tuple) else ""
            raise ValueError(f"{item}too large (allowed: magnitude <= {MAX_MAGNITUDE:g})")
        return value


def did_you_mean(word: str, options: list[str]) -> str:
    """ "; did you mean 'x'? (allowed: ...)" for a name not among ``options``."""
    close = difflib.get_close_matches(word, options, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"{hint} (allowed: {', '.join(sorted(options))})"


def construct(cls: Callable[..., T], config: StrictConfig, **derived: Any) -> T:
    """``cls(...)`` built from a validated config: every field of ``config`` that ``cls``
    takes by the same name, plus the ``derived`` values (a unit converted, an object looked
    up), which win over a field of the same name. A new config field that the core class
    takes needs no line of glue."""
    takes = inspect.signature(cls).parameters
    kwargs = {k: getattr(config, k) for k in type(config).model_fields if k in takes}
    return cls(**{**kwargs, **derived})
