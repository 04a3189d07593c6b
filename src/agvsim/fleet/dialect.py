"""What differs between VDA 5050 2.1.0 and 3.0.0 as far as a vehicle is concerned: field
names, error types and levels, action statuses. The rest of the fleet layer thinks in one
internal vocabulary (``Problem`` kinds) and asks the dialect for the words on the wire."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class Problem(StrEnum):
    """Why a message was refused or an action failed (internal names)."""

    VALIDATION = "validation"  # malformed: JSON, schema, header, structure, sequence ids
    UNSUPPORTED_ACTION = "unsupported_action"  # an action the vehicle cannot perform
    UNSUPPORTED_FIELD = "unsupported_field"  # a field the vehicle cannot use
    OUTDATED_UPDATE = "outdated_update"  # same orderId, lower orderUpdateId
    SAME_UPDATE_CHANGED = "same_update_changed"  # same ids, different content (3.0.0)
    UPDATE_AFTER_CANCEL = "update_after_cancel"
    BAD_STITCH = "bad_stitch"  # an update that does not start at the decision point
    OTHER_ORDER_ACTIVE = "other_order_active"
    START_OUT_OF_RANGE = "start_out_of_range"
    NO_ROUTE = "no_route"  # a node the vehicle cannot locate
    TOO_LARGE = "too_large"  # beyond the factsheet's protocolLimits
    NO_ORDER_TO_CANCEL = "no_order_to_cancel"
    INVALID_INSTANT_ACTION = "invalid_instant_action"
    ACTION_FAILED = "action_failed"  # pick with a full LHD, charging off a charger, ...
    BATTERY_EMPTY = "battery_empty"
    INTERNAL = "internal"  # a fault in the simulated vehicle itself


@dataclass(frozen=True)
class Dialect:
    version: str
    errors: dict[Problem, tuple[str, str]]  # problem -> (errorType, errorLevel)
    has_paused_status: bool
    broken: str  # the connectionState of the last will

    @property
    def major(self) -> str:
        return "v" + self.version.split(".")[0]

    def error(self, kind: Problem) -> tuple[str, str]:
        return self.errors[kind]


V2 = Dialect(
    "2.1.0",
    {
        # the four names the 2.1.0 text defines, and camelCase names of ours beside them
        Problem.VALIDATION: ("validationError", "WARNING"),
        Problem.UNSUPPORTED_ACTION: ("orderError", "WARNING"),
        Problem.UNSUPPORTED_FIELD: ("orderError", "WARNING"),
        Problem.OUTDATED_UPDATE: ("orderUpdateError", "WARNING"),
        Problem.SAME_UPDATE_CHANGED: ("orderUpdateError", "WARNING"),
        Problem.UPDATE_AFTER_CANCEL: ("orderUpdateError", "WARNING"),
        Problem.BAD_STITCH: ("orderUpdateError", "WARNING"),
        Problem.OTHER_ORDER_ACTIVE: ("orderError", "WARNING"),
        Problem.START_OUT_OF_RANGE: ("noRouteError", "WARNING"),
        Problem.NO_ROUTE: ("noRouteError", "WARNING"),
        Problem.TOO_LARGE: ("orderError", "WARNING"),
        Problem.NO_ORDER_TO_CANCEL: ("noOrderToCancel", "WARNING"),
        Problem.INVALID_INSTANT_ACTION: ("instantActionError", "WARNING"),
        Problem.ACTION_FAILED: ("actionError", "WARNING"),
        Problem.BATTERY_EMPTY: ("batteryEmpty", "FATAL"),
        Problem.INTERNAL: ("internalError", "FATAL"),
    },
    has_paused_status=False,  # 2.1.0's state schema has no 'PAUSED' action status
    broken="CONNECTIONBROKEN",
)

V3 = Dialect(
    "3.0.0",
    {
        Problem.VALIDATION: ("VALIDATION_FAILURE", "WARNING"),
        Problem.UNSUPPORTED_ACTION: ("INVALID_ORDER_ACTION", "WARNING"),
        Problem.UNSUPPORTED_FIELD: ("UNSUPPORTED_PARAMETER", "CRITICAL"),
        Problem.OUTDATED_UPDATE: ("OUTDATED_ORDER_UPDATE", "WARNING"),
        Problem.SAME_UPDATE_CHANGED: ("SAME_ORDER_UPDATE_ID", "WARNING"),
        Problem.UPDATE_AFTER_CANCEL: ("ORDER_UPDATE_FOLLOWING_CANCEL", "WARNING"),
        Problem.BAD_STITCH: ("NO_ROUTE_TO_TARGET", "WARNING"),
        Problem.OTHER_ORDER_ACTIVE: ("OTHER_ORDER_ACTIVE", "WARNING"),
        Problem.START_OUT_OF_RANGE: ("START_NODE_OUT_OF_RANGE", "WARNING"),
        Problem.NO_ROUTE: ("NO_ROUTE_TO_TARGET", "WARNING"),
        Problem.TOO_LARGE: ("INSUFFICIENT_MEMORY", "URGENT"),
        Problem.NO_ORDER_TO_CANCEL: ("NO_ORDER_TO_CANCEL", "WARNING"),
        Problem.INVALID_INSTANT_ACTION: ("INVALID_INSTANT_ACTION", "WARNING"),
        Problem.ACTION_FAILED: ("ACTION_FAILED", "CRITICAL"),
        Problem.BATTERY_EMPTY: ("BATTERY_EMPTY", "CRITICAL"),
        Problem.INTERNAL: ("INTERNAL_ERROR", "FATAL"),
    },
    has_paused_status=True,
    broken="CONNECTION_BROKEN",
)

DIALECTS = {d.version: d for d in (V2, V3)}
