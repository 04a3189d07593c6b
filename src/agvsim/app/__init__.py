"""The browser app (``agvsim serve``): a 3D view, the thesis's parameter mask, run controls,
a maze editor and live plots, drawn with viser. ``Session`` (no browser in it) holds the logic;
``App`` adds the viewer."""

from agvsim.app.session import Session

__all__ = ["Session"]
