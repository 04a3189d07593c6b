"""The official VDA 5050 JSON schemas (shipped in ``agvsim/data/vda5050/<version>/``, MIT).

Incoming messages are checked with jsonschema-rs (fast enough for every message of a thousand
vehicles); the tests check outgoing ones with it and with python-jsonschema, the reference.

As published, three of the 3.0.0 schemas (``order``, ``factsheet``, ``visualization``) hold
trailing commas, which strict JSON refuses: ``schema()`` reads every schema tolerantly (a comma
right before ``}`` or ``]`` is dropped) instead of shipping edited copies. Validators are built
once per (version, topic).
"""

from __future__ import annotations

import json
import re
from functools import cache
from importlib import resources
from typing import Any

VERSIONS = ("2.1.0", "3.0.0")
TOPICS = ("order", "instantActions", "state", "visualization", "connection", "factsheet")
_TRAILING_COMMA = re.compile(r",(\s*[}\]])")


@cache
def schema(version: str, topic: str) -> dict:
    """The schema of ``topic`` messages in VDA 5050 ``version`` (read tolerantly)."""
    if version not in VERSIONS:
        raise ValueError(f"VDA 5050 version {version!r} is not supported; supported: {VERSIONS}")
    ref = resources.files("agvsim") / "data" / "vda5050" / version / f"{topic}.schema"
    text = ref.read_text(encoding="utf-8")
    try:
        return dict(json.loads(text))
    except json.JSONDecodeError:
        return dict(json.loads(_TRAILING_COMMA.sub(r"\1", text)))


@cache
def _validator(version: str, topic: str) -> Any:
    import jsonschema_rs

    return jsonschema_rs.validator_for(schema(version, topic), validate_formats=True)


@cache
def _reference_validator(version: str, topic: str) -> Any:
    from jsonschema import FormatChecker
    from jsonschema.validators import validator_for

    s = schema(version, topic)
    cls = validator_for(s)
    cls.check_schema(s)
    return cls(s, format_checker=FormatChecker())


def _path(parts: Any) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(message)"


def problems(version: str, topic: str, message: Any, limit: int = 20) -> list[str]:
    """Every violation of the official schema, one line each with its JSON path (checked by
    jsonschema-rs: a vehicle checks every message it receives, at ~10 us an order)."""
    errors = []
    for e in _validator(version, topic).iter_errors(message):
        errors.append(f"{_path(e.instance_path)}: {e.message}")
        if len(errors) >= limit:
            break
    return sorted(errors)


def reference_problems(version: str, topic: str, message: Any, limit: int = 20) -> list[str]:
    """The same check by the reference implementation (python-jsonschema), for the tests."""
    errors = sorted(
        _reference_validator(version, topic).iter_errors(message), key=lambda e: list(e.path)
    )
    return [f"{_path(e.absolute_path)}: {e.message}" for e in errors[:limit]]
