"""plot.png draws the world's guidance infrastructure: tape, its spots, floor codes and
reflectors, each where the world has them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from agvsim.sensors.floor_codes import FloorCodeGrid
from agvsim.sensors.reflectors import ReflectorMap
from agvsim.viz.plot import _draw_guidance
from agvsim.world.tape import Spot, Tape


def test_guidance_is_drawn_where_the_world_has_it():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    world = SimpleNamespace(
        tape=Tape([[(0.0, 0.0), (2.0, 0.0), (2.0, 1.0)]], spots=[Spot(2.0, 0.0, 5)]),
        floor_codes=FloorCodeGrid(cols=3, rows=2, spacing_m=1.0, size_m=0.05),
        reflectors=ReflectorMap(np.array([[5.0, 5.0], [6.0, 5.0]])),
    )
    fig, ax = plt.subplots()
    _draw_guidance(ax, world)
    (tape,) = ax.collections
    np.testing.assert_allclose(tape.get_segments()[1], [[2.0, 0.0], [2.0, 1.0]])
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    np.testing.assert_allclose(lines["tape spots"].get_xydata(), [[2.0, 0.0]])
    assert len(lines["floor codes"].get_xydata()) == 6
    np.testing.assert_allclose(lines["reflectors"].get_xydata(), [[5.0, 5.0], [6.0, 5.0]])
    plt.close(fig)
    fig, ax = plt.subplots()
    _draw_guidance(ax, SimpleNamespace(tape=None, floor_codes=None, reflectors=None))
    assert not ax.collections and not ax.get_lines()
    plt.close(fig)
