"""Read YAML that a careless user or an attacker wrote, within a budget.

PyYAML's ``safe_load`` runs no code, but it still accepts inputs that make everything after it
hang or crash: an alias bomb ("billion laughs") is a few hundred bytes that expand into 10^9
nodes when anything walks the data; 50,000 nested brackets end in a ``RecursionError``; a
UTF-16 or Latin-1 file ends in a ``UnicodeDecodeError``. :func:`load_yaml` refuses all three
before any Python object is built:

1. the bytes must be UTF-8 (a byte-order mark is allowed) and at most ``max_bytes`` long;
2. one pass over the parser's events (a flat loop, no recursion) measures the nesting depth
   and the number of nodes the document holds *with every alias expanded* (an anchored
   collection's expanded size is remembered, so the count costs one pass however large the
   expansion is);
3. only then is the document constructed (with libyaml when it is installed).

Every refusal is a :class:`YamlInputError` (a ``ValueError``) whose message names the source,
the line, the limit and how to raise it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

__all__ = ["YamlInputError", "YamlLimits", "load_yaml", "load_yaml_file", "measure_data"]
_CONTAINERS = (dict, list, tuple)

try:  # libyaml: ~10x faster
    from yaml.cyaml import CParser as _Parser
    from yaml.cyaml import CSafeLoader as _Loader
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    _Parser, _Loader = None, yaml.SafeLoader  # type: ignore[assignment,misc]


@dataclass(frozen=True)
class YamlLimits:
    """What a YAML document may hold. The defaults fit any hand-written scenario or map file
    with room to spare; large maps belong in a map file (``world.file``), not inline."""

    max_bytes: int = 16 * 1024 * 1024  # file size
    max_nodes: int = 250_000  # scalars + lists + mappings, aliases expanded
    max_depth: int = 64  # nested lists / mappings

    def __post_init__(self) -> None:
        for name in ("max_bytes", "max_nodes", "max_depth"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"YamlLimits.{name} must be a positive integer, got {value!r}")


class YamlInputError(ValueError):
    """YAML input that is refused; ``line`` is 1-based when known."""

    def __init__(self, source: str, problem: str, line: int | None = None):
        self.source, self.problem, self.line = source, problem, line
        where = f"line {line}: " if line is not None else ""
        super().__init__(f"{source}: {where}{problem}")


def _decode(data: bytes, source: str) -> str:
    boms = {b"\xff\xfe": "UTF-16", b"\xfe\xff": "UTF-16", b"\xff\xfe\x00\x00": "UTF-32"}
    for bom, name in boms.items():
        if data.startswith(bom):
            raise YamlInputError(source, f"the file is {name} text; save it as UTF-8")
    nul = data.find(b"\x00")
    if nul >= 0:
        raise YamlInputError(
            source,
            "byte 0x00 (NUL) is not allowed in a text file (UTF-16 without a byte-order mark?); "
            "save it as UTF-8",
            data[:nul].count(b"\n") + 1,
        )
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        byte = data[err.start]
        raise YamlInputError(
            source, f"byte {byte:#04x} is not UTF-8 text; save the file as UTF-8", line
        ) from None


def _yaml_problem(err: Exception, text: str) -> tuple[str, int | None]:
    """(what is wrong, 1-based line) of a PyYAML error."""
    mark = getattr(err, "problem_mark", None)
    line = None if mark is None else int(mark.line) + 1
    position = getattr(err, "position", None)  # a ReaderError: a character index
    if line is None and isinstance(position, int):
        line = text.count("\n", 0, position) + 1
    problem = getattr(err, "problem", None)
    if problem is None and isinstance(err, yaml.reader.ReaderError):
        problem = f"character {err.character!r} is not allowed in YAML"  # type: ignore[attr-defined]
    lines = str(problem or err).strip().splitlines()
    return (lines[0] if lines else type(err).__name__), line


def _line(event: Any) -> int | None:
    return event.start_mark.line + 1 if event.start_mark is not None else None


def _measure(text: str, source: str, limits: YamlLimits) -> None:
    """Walk the parser's events once; refuse a document too deep or too large when expanded.

    ``total`` counts every value seen so far, each alias as the expanded size of its anchor
    (a collection's size is known at its end event and kept by anchor name)."""
    parser = _Parser(text) if _Parser is not None else yaml.SafeLoader(text)
    scalar, alias, start, end = (
        yaml.ScalarEvent,
        yaml.AliasEvent,
        (yaml.SequenceStartEvent, yaml.MappingStartEvent),
        (yaml.SequenceEndEvent, yaml.MappingEndEvent),
    )
    stack: list[list[Any]] = [[None, 0]]  # per open collection: [anchor, values so far]
    sizes: dict[str, int] = {}
    total = 0
    try:
        while (event := parser.get_event()) is not None:
            kind = type(event)
            if kind is scalar:
                size = 1
                if event.anchor is not None:
                    sizes[event.anchor] = 1
            elif kind is alias:
                size = sizes.get(event.anchor, 1)  # an unknown anchor: PyYAML reports it later
            elif kind in start:
                if len(stack) > limits.max_depth:
                    raise YamlInputError(
                        source,
                        f"lists/mappings nested deeper than {limits.max_depth} levels "
                        "(limit yaml_max_depth; see docs/scenario.md, 'Limits')",
                        _line(event),
                    )
                stack.append([event.anchor, 1])  # the collection itself counts as one
                total += 1
                continue
            elif kind in end:
                anchor, inner = stack.pop()
                if anchor is not None:
                    sizes[anchor] = inner
                stack[-1][1] += inner  # already in total
                continue
            else:  # stream / document start and end
                continue
            stack[-1][1] += size
            total += size
            if total > limits.max_nodes:
                what = "aliases expand" if kind is alias else "it grows"
                raise YamlInputError(
                    source,
                    f"the document holds more than {limits.max_nodes:,} values ({what} past "
                    "the limit yaml_max_nodes; see docs/scenario.md, 'Limits')",
                    _line(event),
                )
        if total > limits.max_nodes:  # the last collection's own count
            raise YamlInputError(
                source,
                f"the document holds more than {limits.max_nodes:,} values "
                "(limit yaml_max_nodes; see docs/scenario.md, 'Limits')",
            )
    finally:
        dispose = getattr(parser, "dispose", None)
        if dispose is not None:
            dispose()


def _too_big(source: str, size: int, limits: YamlLimits) -> YamlInputError:
    return YamlInputError(
        source,
        f"the file is {size:,} bytes, over the limit yaml_max_bytes = {limits.max_bytes:,} "
        "(see docs/scenario.md, 'Limits')",
    )


def load_yaml(text: str | bytes, source: str, limits: YamlLimits | None = None) -> Any:
    """The data of one YAML document (``safe_load``), refused with :class:`YamlInputError`
    when it breaks ``limits`` (size, nesting depth, nodes with aliases expanded), is not
    UTF-8 or is not valid YAML."""
    limits = limits or YamlLimits()
    size = len(text) if isinstance(text, bytes) else len(text.encode("utf-8", "surrogatepass"))
    if size > limits.max_bytes:
        raise _too_big(source, size, limits)
    if isinstance(text, bytes):
        text = _decode(text, source)
    try:
        _measure(text, source, limits)
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a safe loader
    except yaml.YAMLError as err:
        problem, line = _yaml_problem(err, text)
        raise YamlInputError(source, f"not valid YAML ({problem})", line) from None
    except (ValueError, RecursionError, MemoryError) as err:
        if isinstance(err, YamlInputError):
            raise
        # e.g. an integer of more than 4300 digits (Python refuses to convert it)
        digits = re.search(r"\d{4000,}", text)
        line = None if digits is None else text.count("\n", 0, digits.start()) + 1
        problem = f"not valid YAML ({type(err).__name__}: {str(err)[:200]})"
        raise YamlInputError(source, problem, line) from None


def load_yaml_file(path: str | Path, limits: YamlLimits | None = None) -> Any:
    """:func:`load_yaml` of a file; the size is checked before the file is read."""
    p = Path(path)
    limits = limits or YamlLimits()
    try:
        size = p.stat().st_size
        if size > limits.max_bytes:
            raise _too_big(str(p), size, limits)
        data = p.read_bytes()
    except OSError as err:
        raise YamlInputError(str(p), f"cannot read the file ({err.strerror or err})") from None
    return load_yaml(data, str(p), limits)


def measure_data(data: Any, source: str, limits: YamlLimits | None = None) -> int:
    """The number of values in ``data`` (dicts, lists, tuples and scalars) with shared
    sub-structures counted every time they appear, as anything walking it would see them;
    YamlInputError past ``limits.max_nodes`` or deeper than ``limits.max_depth``.

    The safety net for data that did not come through :func:`load_yaml` (e.g. a PyYAML
    ``safe_load`` elsewhere, where an alias bomb is a few shared lists): each container is
    measured once, so a bomb costs its size in memory, not its expansion. Iterative; a
    container that holds itself is measured as one value at the point it recurs."""
    limits = limits or YamlLimits()
    if not isinstance(data, dict | list | tuple):
        return 1
    sizes: dict[int, int] = {}
    open_: set[int] = set()
    # (container, depth, its container children once expanded (None before), its length)
    stack: list[tuple[Any, int, list | None, int]] = [(data, 1, None, 0)]
    while stack:
        obj, depth, kids, length = stack.pop()
        key = id(obj)
        if kids is not None:  # all its children are measured
            open_.discard(key)
            size = 1 + length + sum(sizes.get(id(c), 1) - 1 for c in kids)
            sizes[key] = size
            if size > limits.max_nodes:
                raise YamlInputError(
                    source,
                    f"the data holds more than {limits.max_nodes:,} values (shared parts "
                    "counted each time; limit yaml_max_nodes, see docs/scenario.md, 'Limits')",
                )
            continue
        if key in sizes or key in open_:
            continue
        if depth > limits.max_depth:
            raise YamlInputError(
                source,
                f"lists/mappings nested deeper than {limits.max_depth} levels "
                "(limit yaml_max_depth; see docs/scenario.md, 'Limits')",
            )
        open_.add(key)
        items = [*obj.keys(), *obj.values()] if isinstance(obj, dict) else obj
        kids = [c for c in items if isinstance(c, _CONTAINERS)]
        stack.append((obj, depth, kids, len(items)))
        stack.extend((c, depth + 1, None, 0) for c in kids if id(c) not in sizes)
    return sizes.get(id(data), 1)
