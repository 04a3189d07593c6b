"""The thesis's Simulink "mask" as data: which fields a robot's panel shows, and how the values
typed into them become a robot entry of a scenario file.

``mask_fields(robot)`` lists the fields for a robot entry (its model decides the parameter
fields); ``robot_from_mask(robot, values)`` writes the panel's values back into a copy of the
entry. Validation is not done here: the app validates the result with the scenario schema, so
the panel shows the same messages a scenario file would get.
"""

from __future__ import annotations

import copy
import typing
from dataclasses import dataclass
from typing import Any, Literal

import yaml
from pydantic import BaseModel

from agvsim.behaviours import BEHAVIOURS
from agvsim.kinematics import MODELS
from agvsim.safe_yaml import YamlInputError, load_yaml
from agvsim.scenario import default_camera_height, default_rate_hz
from agvsim.scenario_dynamics import DynamicsConfig
from agvsim.scenario_params import PARAMS
from agvsim.scenario_schema import (
    Body,
    CameraConfig,
    LidarConfig,
    Pose,
    RangersConfig,
    Scenario,
)

Kind = Literal["text", "number", "int", "dropdown", "checkbox", "yaml"]


@dataclass(frozen=True)
class Field:
    key: str  # dotted path in the robot entry, e.g. "params.wheel_radius_m"
    label: str
    kind: Kind
    value: Any
    options: tuple[str, ...] = ()
    step: float = 0.01
    hint: str = ""


def controller_types(allow_python: bool = False) -> list[str]:
    """Every controller ``type`` a scenario accepts (python only when allowed)."""
    return [tag for tag in BEHAVIOURS if tag != "python" or allow_python]


# which keys of each sensor the panel shows; defaults and labels come from the schema
SENSOR_FIELDS: dict[str, tuple[type[BaseModel], tuple[str, ...]]] = {
    "rangers": (RangersConfig, ("range_max_m", "rate_hz", "noise_std_m")),
    "lidar": (LidarConfig, ("beams", "fov_deg", "range_max_m", "rate_hz", "noise_std_m")),
    "camera": (
        CameraConfig,
        ("width_px", "height_px", "hfov_deg", "rate_hz", "range_max_m", "mount_z_m", "pitch_deg",
         "noise_std"),
    ),
}  # fmt: skip
DEFAULT_DT_S = float(Scenario.model_fields["dt_s"].default)  # a scenario without dt_s


# the dynamics block's main values (agvsim.dynamics); the rest stays as the file has it
DYNAMICS_FIELDS = [
    ("mass_kg", "mass (kg)"),
    ("load.mass_kg", "load (kg)"),
    ("motor.torque_max_nm", "motor torque limit (N m)"),
    ("motor.gear_ratio", "gear ratio"),
    ("motor.time_constant_s", "speed controller time constant (s)"),
    ("slip_speed_m_s", "tyre slip speed (m/s)"),
]


def _dyn_default(key: str) -> Any:
    obj: Any = DynamicsConfig()
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj


def _dyn_get(block: dict, key: str) -> Any:
    for part in key.split("."):
        if not isinstance(block, dict) or part not in block:
            return None
        block = block[part]
    return block


UNITS = (("_rad_s", "rad/s"), ("_m_s", "m/s"), ("_rad", "rad"), ("_deg", "deg"), ("_hz", "Hz"),
         ("_px", "px"), ("_m", "m"), ("_s", "s"))  # fmt: skip


def _unit(name: str) -> tuple[str, str]:
    """``wheel_radius_m`` -> (``wheel_radius``, ``m``); no unit suffix: (name, "")."""
    for suffix, unit in UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)], unit
    return name, ""


def plain_label(name: str) -> str:
    """A parameter's name as the panel shows it: ``wheel_radius_m`` -> ``wheel radius (m)``,
    ``max_steer_rate_rad_s`` -> ``max steer rate (rad/s)``."""
    stem, unit = _unit(name)
    return f"{stem.replace('_', ' ')} ({unit})" if unit else stem.replace("_", " ")


def schema_label(config: type[BaseModel], name: str) -> str:
    """The label of a schema field: its ``title`` (with the unit its name carries), or its
    name in plain words."""
    title = config.model_fields[name].title
    if not title:
        return plain_label(name)
    unit = _unit(name)[1]
    return f"{title} ({unit})" if unit and "(" not in title else title


def fields_in_error(problems: list[str], robot: dict) -> dict[str, str]:
    """Mask field key -> the problem that names it, for the scenario schema's ``problems``
    about the robot entry ``robot`` (``robots[k].body.length_m: ...``,
    ``robots[k].sensors[1].lidar.range_max_m: ...``, ``robots[k].controller...``)."""
    out: dict[str, str] = {}
    kinds = [s.get("type") for s in robot.get("sensors", [])]
    for text in problems:
        path = text.split(":", 1)[0]
        parts = path.split(".")[1:] if path.startswith("robots[") else path.split(".")
        if not parts:
            continue
        head = parts[0]
        if head in ("params", "body", "pose") and len(parts) > 1:
            out.setdefault(f"{head}.{parts[1]}", text)
        elif head in ("name", "model", "mode"):
            out.setdefault(head, text)
        elif head.startswith("sensors["):
            try:
                kind = kinds[int(head[len("sensors[") : -1])]
            except (ValueError, IndexError):
                continue
            key = parts[2] if len(parts) > 2 else ""
            target = f"sensors.{kind}.{key}"
            out.setdefault(target if key else f"sensors.{kind}", text)
        elif head == "controller":
            out.setdefault("controller.settings", text)
        elif head == "safety":
            out.setdefault("safety", text)
    return out


def _sensor_default(robot: dict, kind: str, key: str, dt_s: float) -> Any:
    """The value the panel shows for an unset sensor key: the schema's default, or the one
    agvsim.scenario derives when the schema's is None (a range sensor's rate from ``dt_s``,
    the camera's height 5 cm above the body)."""
    default = SENSOR_FIELDS[kind][0].model_fields[key].default
    if default is not None:
        return default
    if key == "rate_hz":
        return default_rate_hz(kind, dt_s)
    if key != "mount_z_m":
        return None
    model = robot.get("model", "differential")
    r = robot.get("params", {}).get("wheel_radius_m")
    if r is None and model in PARAMS:
        r = PARAMS[model].model_fields["wheel_radius_m"].default
    return round(default_camera_height(r if r is not None else 0.1), 9)


def _kind_of(config: type[BaseModel], key: str) -> Kind:
    return "int" if config.model_fields[key].annotation is int else "number"


def _sensor(robot: dict, kind: str) -> dict | None:
    for s in robot.get("sensors", []):
        if s.get("type") == kind:
            return s
    return None


def mask_fields(robot: dict, allow_python: bool = False, dt_s: float = DEFAULT_DT_S) -> list[Field]:
    """The panel's fields for ``robot`` (a robot entry of a scenario, as a dict, in a scenario
    stepping ``dt_s``)."""
    model = robot.get("model", "differential")
    params_config = PARAMS[model]
    params = robot.get("params", {})
    body = robot.get("body", {})
    pose = robot.get("pose", {})
    out = [
        Field("name", "name", "text", robot.get("name", "")),
        Field("model", "model", "dropdown", model, tuple(MODELS)),
        Field(
            "mode",
            "kinematics",
            "dropdown",
            robot.get("mode", "inverse"),
            ("inverse", "forward"),
            hint="inverse: the controller gives a body twist; forward: wheel speeds",
        ),
    ]
    for name, f in params_config.model_fields.items():
        v = params.get(name, f.default)
        label, hint = schema_label(params_config, name), f.description or ""
        choices = typing.get_args(f.annotation)
        if typing.get_origin(f.annotation) is Literal:
            opts = tuple(str(c) for c in choices)
            out.append(Field(f"params.{name}", label, "dropdown", v, opts, hint=hint))
        else:
            out.append(Field(f"params.{name}", label, "number", float(v), step=0.01, hint=hint))
    for key in ("length_m", "width_m"):
        v = body.get(key, Body.model_fields[key].default)
        out.append(Field(f"body.{key}", f"body {schema_label(Body, key)}", "number", v))
    for key, step in (("x_m", 0.1), ("y_m", 0.1), ("theta_deg", 1.0)):
        v = pose.get(key, Pose.model_fields[key].default)
        label = f"initial {schema_label(Pose, key)}"
        out.append(Field(f"pose.{key}", label, "number", v, step=step))
    for kind, (config, keys) in SENSOR_FIELDS.items():
        s = _sensor(robot, kind)
        out.append(Field(f"sensors.{kind}", f"{kind} on", "checkbox", s is not None))
        for key in keys:
            unset = s is None or s.get(key) is None
            v = _sensor_default(robot, kind, key, dt_s) if unset else s[key]  # type: ignore[index]
            label = f"{kind} {schema_label(config, key)}"
            out.append(Field(f"sensors.{kind}.{key}", label, _kind_of(config, key), v))
    dyn = robot.get("dynamics")
    out.append(
        Field(
            "dynamics",
            "dynamics on",
            "checkbox",
            dyn is not None,
            hint="mass, motors, friction and wheel slip (docs/dynamics.md)",
        )  # fmt: skip
    )
    for key, label in DYNAMICS_FIELDS:
        v = _dyn_get(dyn or {}, key)
        out.append(Field(f"dynamics.{key}", label, "number", _dyn_default(key) if v is None else v))
    ctrl = dict(robot.get("controller", {"type": "idle"}))
    ctype = ctrl.pop("type", "idle")
    out.append(
        Field(
            "controller.type",
            "controller",
            "dropdown",
            ctype,
            tuple(controller_types(allow_python or ctype == "python")),
        )
    )
    text = yaml.safe_dump(ctrl, sort_keys=False, default_flow_style=None).strip()
    out.append(
        Field(
            "controller.settings",
            "controller settings",
            "yaml",
            "" if text == "{}" else text,
            hint="YAML: the controller's keys as in a scenario file (see docs/scenario.md)",
        )
    )
    out.append(safety_field(robot))
    return out


def safety_field(robot: dict) -> Field:
    """The robot's ``safety:`` block (a safety scanner's field sets) as YAML text."""
    block = robot.get("safety")
    text = "" if not block else yaml.safe_dump(block, sort_keys=False, default_flow_style=None)
    return Field(
        "safety",
        "safety scanner",
        "yaml",
        text.strip(),
        hint="YAML: the robot's safety: block (sensor, field_sets, response_time_s, ...; "
        "docs/safety_fields.md); empty: no scanner",
    )


def _safety_from_mask(out: dict, text: str) -> None:
    """The safety field's YAML into ``out`` (empty text: no scanner)."""
    try:  # the scenario loader's bounded reader (size, depth, aliases)
        block = load_yaml(text, "safety scanner") if text.strip() else None
    except YamlInputError as err:
        raise MaskError(str(err)) from None
    if block is None:
        out.pop("safety", None)
    elif isinstance(block, dict):
        out["safety"] = block
    else:
        raise MaskError(f"safety scanner: need 'key: value' lines, got {type(block).__name__}")


class MaskError(ValueError):
    """A field the panel cannot even turn into a scenario entry (e.g. unreadable YAML)."""


def robot_from_mask(robot: dict, values: dict[str, Any], dt_s: float = DEFAULT_DT_S) -> dict:
    """A copy of ``robot`` with the panel's ``values`` (field key -> value) written in (the
    scenario steps ``dt_s``, as for :func:`mask_fields`)."""
    out = copy.deepcopy(robot)
    model_changed = "model" in values and values["model"] != robot.get("model")
    for key in ("name", "model", "mode"):
        if key in values:
            out[key] = values[key]
    if model_changed:  # the old model's parameters mean nothing to the new one
        out["params"] = {}
    names = {n: f.default for n, f in PARAMS[out["model"]].model_fields.items()}
    params = dict(out.get("params", {}))
    for key, v in values.items():
        if key.startswith("params.") and not model_changed:
            p = key.removeprefix("params.")
            if p in names and v != names[p]:
                params[p] = v
            elif p in names:
                params.pop(p, None)
    out["params"] = params
    for group in ("body", "pose"):
        sub = dict(out.get(group, {}))
        for key, v in values.items():
            if key.startswith(group + "."):
                sub[key.split(".", 1)[1]] = v
        out[group] = sub
    # the mask shows the first sensor of each kind; further ones (a second camera) stay as they are
    shown = [id(_sensor(out, kind)) for kind in SENSOR_FIELDS]
    sensors = [s for s in out.get("sensors", []) if id(s) not in shown]
    for kind in SENSOR_FIELDS:
        on = values.get(f"sensors.{kind}", _sensor(robot, kind) is not None)
        if not on:
            continue
        s = dict(_sensor(robot, kind) or {"type": kind})
        config, keys = SENSOR_FIELDS[kind]
        for key in keys:
            v = values.get(f"sensors.{kind}.{key}")
            # keys the entry leaves unset stay unset while the panel shows their default
            if v is not None and (key in s or v != _sensor_default(robot, kind, key, dt_s)):
                s[key] = int(round(v)) if _kind_of(config, key) == "int" else v
        sensors.append(s)
    out["sensors"] = sensors
    if "dynamics" in values:
        _dynamics_from_mask(out, robot, values)
    if "controller.type" in values or "controller.settings" in values:
        ctype = values.get("controller.type", robot.get("controller", {}).get("type", "idle"))
        text = values.get("controller.settings", "") or ""
        try:  # the scenario loader's bounded reader (size, depth, aliases)
            settings = load_yaml(text, "controller settings") if text.strip() else {}
        except YamlInputError as err:
            raise MaskError(str(err)) from None
        if not isinstance(settings, dict):
            raise MaskError(
                f"controller settings: need 'key: value' lines, got {type(settings).__name__}"
            )
        settings.pop("type", None)
        out["controller"] = {"type": ctype, **settings}
    if "safety" in values:
        _safety_from_mask(out, values["safety"] or "")
    return out


def _dynamics_from_mask(out: dict, robot: dict, values: dict[str, Any]) -> None:
    """The dynamics checkbox and fields into ``out``; keys the entry leaves unset stay unset
    while the panel shows their default."""
    if not values["dynamics"]:
        out.pop("dynamics", None)
        return
    block = copy.deepcopy(robot.get("dynamics") or {})
    for key, _label in DYNAMICS_FIELDS:
        v = values.get(f"dynamics.{key}")
        if v is None or (_dyn_get(block, key) is None and v == _dyn_default(key)):
            continue
        *path, last = key.split(".")
        sub = block
        for part in path:
            sub = sub.setdefault(part, {})
        sub[last] = v
    out["dynamics"] = block
