"""Dotted paths into a scenario's data (the YAML mapping, before validation).

``robots.0.params.wheel_radius_m`` walks ``data["robots"][0]["params"]["wheel_radius_m"]``.
A list item is picked by its index, or by its ``name`` (``robots.red.controller.speed_m_s``);
a sensor without a ``name`` is named by its ``type`` (``robots.0.sensors.lidar.noise_std_m``),
as in the scenario. Missing mappings on the way are created (``robots.0.params`` need not be
in the base scenario); the schema then judges the result.
"""

from __future__ import annotations

import copy
import difflib
from typing import Any


class PathError(ValueError):
    """A path that does not lead anywhere in the data; the message names the path."""


def set_path(data: dict, path: str, value: Any) -> None:
    """Set ``value`` (a copy of it) at ``path`` in ``data``, in place."""
    parts = split_path(path)
    node: Any = data
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        walked = ".".join(parts[:depth]) or "the scenario"
        if isinstance(node, dict):
            if last:
                node[part] = copy.deepcopy(value)
                return
            if node.get(part) is None:
                node[part] = {}
            node = node[part]
        elif isinstance(node, list):
            k = _list_index(node, part, path, walked)
            if last:
                node[k] = copy.deepcopy(value)
                return
            node = node[k]
        else:
            raise PathError(f"{path}: {walked} is {node!r}, not a mapping or a list")


def get_path(data: Any, path: str) -> Any:
    """The value at ``path`` (PathError when there is none)."""
    node = data
    parts = split_path(path)
    for depth, part in enumerate(parts):
        walked = ".".join(parts[:depth]) or "the scenario"
        if isinstance(node, dict):
            if part not in node:
                raise PathError(f"{path}: {walked} has no key {part!r}")
            node = node[part]
        elif isinstance(node, list):
            node = node[_list_index(node, part, path, walked)]
        else:
            raise PathError(f"{path}: {walked} is {node!r}, not a mapping or a list")
    return node


def split_path(path: str) -> list[str]:
    parts = str(path).split(".")
    if not path or any(p.strip() == "" for p in parts):
        raise PathError(f"{path!r} is not a dotted path such as robots.0.params.wheel_radius_m")
    return parts


def _list_index(items: list, part: str, path: str, walked: str) -> int:
    if part.lstrip("-").isdigit():
        k = int(part)
        if not 0 <= k < len(items):
            raise PathError(
                f"{path}: {walked} has {len(items)} item(s), so index {k} is out of range "
                f"(allowed: 0..{len(items) - 1})"
            )
        return k
    names = [_item_name(it) for it in items]
    hits = [k for k, n in enumerate(names) if n == part]
    if len(hits) == 1:
        return hits[0]
    known = [n for n in names if n is not None]
    if not hits:
        close = difflib.get_close_matches(part, known, n=1, cutoff=0.6)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise PathError(
            f"{path}: {walked} has no item named {part!r}{hint} "
            f"(give an index 0..{len(items) - 1} or one of: {', '.join(map(str, known)) or '-'})"
        )
    raise PathError(f"{path}: {walked} has {len(hits)} items named {part!r}; use an index")


def _item_name(item: Any) -> str | None:
    if not isinstance(item, dict):
        return None
    name = item.get("name")
    if name is None:
        name = item.get("type")  # a sensor's default name is its type
    return None if name is None else str(name)
