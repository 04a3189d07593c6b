"""Checking an incoming message before the vehicle looks at its content: size, JSON, the
official schema, the protocol's major version, and that it is addressed to this vehicle."""

from __future__ import annotations

import json
from typing import Any

from agvsim.fleet.dialect import Problem
from agvsim.fleet.order import OrderRefused
from agvsim.fleet.schemas import problems as schema_problems


def decode(
    payload: Any, topic: str, version: str, max_bytes: int, manufacturer: str, serial: str
) -> dict:
    """The message as a dict (``payload``: bytes, str or an already parsed dict), or
    ``OrderRefused(VALIDATION, ...)`` with references (topic, headerId, orderId ...)."""
    refs: dict[str, str] = {"topic": topic}
    msg = payload
    if isinstance(payload, bytes | bytearray | str):
        if len(payload) > max_bytes:
            raise OrderRefused(
                Problem.VALIDATION,
                f"message of {len(payload)} bytes; this vehicle takes at most {max_bytes}",
                refs,
            )
        try:
            msg = json.loads(payload)
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise OrderRefused(Problem.VALIDATION, f"not valid JSON: {err}", refs) from None
    if not isinstance(msg, dict):
        raise OrderRefused(Problem.VALIDATION, "the message is not a JSON object", refs)
    for key in ("headerId", "orderId", "orderUpdateId"):
        value = msg.get(key)
        if isinstance(value, str | int) and not isinstance(value, bool):
            refs[key] = str(value)
    found = schema_problems(version, topic, msg, limit=3)
    if found:
        raise OrderRefused(
            Problem.VALIDATION,
            f"does not match the VDA 5050 {version} {topic} schema: " + "; ".join(found),
            refs,
        )
    if str(msg["version"]).split(".")[0] != version.split(".")[0]:
        raise OrderRefused(
            Problem.VALIDATION,
            f"version {msg['version']!r}: this vehicle speaks VDA 5050 {version}",
            refs,
        )
    if (msg["manufacturer"], msg["serialNumber"]) != (manufacturer, serial):
        raise OrderRefused(
            Problem.VALIDATION,
            f"addressed to {msg['manufacturer']}/{msg['serialNumber']}, not to this vehicle",
            refs,
        )
    return msg
