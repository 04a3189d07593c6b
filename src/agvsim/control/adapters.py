"""Adapters that let a twist-commanding behaviour drive a robot in forward (wheel) mode."""

from __future__ import annotations

import numpy as np

from agvsim.control.api import BatchController, BatchObservation
from agvsim.kinematics.actuation import forward_command
from agvsim.kinematics.base import KinematicModel


class WheelsFromTwist:
    """Wraps a batch controller that outputs twists ``(k, 3)`` and hands the engine driven
    wheel speeds (+ steering), computed with the robots' own inverse kinematics."""

    def __init__(self, inner: BatchController, model: KinematicModel):
        self.inner, self.model = inner, model

    def reset(self, k: int, rng: np.random.Generator) -> None:
        self.inner.reset(k, rng)

    def step(self, obs: BatchObservation) -> np.ndarray:
        return forward_command(self.model, np.asarray(self.inner.step(obs), dtype=np.float64))

    def __getattr__(self, name: str):  # state names etc. come from the wrapped behaviour
        if name == "inner":  # not set yet (copying, unpickling)
            raise AttributeError(name)
        return getattr(self.inner, name)
