"""The typed ``params`` block of each kinematic model, derived from the model's dataclass.

``PARAMS[kind]`` is a strict config class whose fields are the dataclass's fields: the same
names (units in them), defaults, one-line descriptions and allowed values (``param(...,
bounds)`` in :mod:`agvsim.kinematics.params`, and ``Literal`` choices). Nothing here repeats
a model's parameters: a new model in ``kinematics.MODELS`` gets its block for free.

A number keeps the type the file gave it (an integer stays an integer, as the dataclass
would receive it from Python), so a scenario read back or recorded shows what was written.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import fields
from typing import Annotated, Any, Literal

from pydantic import Field, PlainValidator, create_model

from agvsim.config_base import StrictConfig
from agvsim.kinematics import MODELS
from agvsim.kinematics.params import Bounds, bounds_of, choices_of
from agvsim.scenario_limits import MAX_MAGNITUDE


def _number_check(bounds: Bounds | None) -> Callable[[Any], Any]:
    def check(value: Any) -> Any:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError("must be a number")
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError("must be a finite number (NaN and inf are not allowed)")
        if abs(value) > MAX_MAGNITUDE:  # before any float(): an int of 400 digits has none
            raise ValueError(f"too large (allowed: magnitude <= {MAX_MAGNITUDE:g})")
        if bounds is not None and not bounds.holds(value):
            raise ValueError(f"must be {bounds.describe()}")
        return value

    return check


def params_config(kind: str, model: type) -> type[StrictConfig]:
    """The strict ``params`` config of the kinematic dataclass ``model`` (named ``kind``)."""
    choices = choices_of(model)
    spec: dict[str, Any] = {}
    for f in fields(model):
        doc = f.metadata.get("doc", "")
        if f.name in choices:
            ann: Any = Literal[choices[f.name]]
        else:
            ann = Annotated[int | float, PlainValidator(_number_check(bounds_of(f)))]
        spec[f.name] = (ann, Field(default=f.default, description=doc))
    return create_model(  # type: ignore[call-overload,no-any-return]
        f"{model.__name__}Params",
        __base__=StrictConfig,
        __doc__=f"The ``params`` of a ``{kind}`` robot (agvsim.kinematics.{model.__name__}).",
        **spec,
    )


PARAMS: dict[str, type[StrictConfig]] = {kind: params_config(kind, m) for kind, m in MODELS.items()}


def build_model(kind: str, params: StrictConfig) -> Any:
    """The kinematic model of a robot entry: the dataclass ``MODELS[kind]`` with its validated
    ``params`` (the ones the file left out take the dataclass's own defaults)."""
    return MODELS[kind](**{k: getattr(params, k) for k in params.model_fields_set})
