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
from dataclasses import fields as dc_fields
from typing import Any, Literal

import yaml

from agvsim.kinematics import MODELS
from agvsim.safe_yaml import YamlInputError, load_yaml
from agvsim.scenario import default_camera_height
from agvsim.scenario_dynamics import DynamicsConfig
from agvsim.scenario_schema import ControllerConfig

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
    union = typing.get_args(typing.get_args(ControllerConfig)[0])
    out = []
    for cls in union:
        (tag,) = typing.get_args(cls.model_fields["type"].annotation)
        if tag != "python" or allow_python:
            out.append(tag)
    return out


SENSOR_FIELDS = {
    "rangers": [
        ("range_max_m", "range (m)", "number", 1.0),
        ("rate_hz", "rate (Hz)", "number", 50.0),
        ("noise_std_m", "noise std (m)", "number", 0.0),
    ],
    "lidar": [
        ("beams", "beams", "int", 240),
        ("fov_deg", "field of view (deg)", "number", 360.0),
        ("range_max_m", "range (m)", "number", 10.0),
        ("rate_hz", "rate (Hz)", "number", 10.0),
        ("noise_std_m", "noise std (m)", "number", 0.0),
    ],
    "camera": [
        ("width_px", "width (px)", "int", 320),
        ("height_px", "height (px)", "int", 240),
        ("hfov_deg", "field of view (deg)", "number", 60.0),
        ("rate_hz", "rate (Hz)", "number", 10.0),
        ("range_max_m", "range (m)", "number", 30.0),
        ("mount_z_m", "mount height (m)", "number", None),  # None: see _default
        ("pitch_deg", "pitch down (deg)", "number", 0.0),
        ("noise_std", "noise std (0..255)", "number", 0.0),
    ],
}


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


def plain_label(name: str) -> str:
    """A parameter's name as the panel shows it: ``wheel_radius_m`` -> ``wheel radius (m)``,
    ``max_steer_rate_rad_s`` -> ``max steer rate (rad/s)``."""
    for suffix, unit in UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return f"{name[: -len(suffix)].replace('_', ' ')} ({unit})"
    return name.replace("_", " ")


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
    return out


def _default(robot: dict, key: str, default: Any) -> Any:
    """The value the panel shows for an unset sensor key: the schema's default, or for the
    camera's height the one agvsim.scenario derives (5 cm above the body)."""
    if key != "mount_z_m":
        return default
    model = robot.get("model", "differential")
    r = robot.get("params", {}).get("wheel_radius_m")
    if r is None:
        r = next((f.default for f in dc_fields(MODELS[model]) if f.name == "wheel_radius_m"), 0.1)
    return round(default_camera_height(r), 9)


def _sensor(robot: dict, kind: str) -> dict | None:
    for s in robot.get("sensors", []):
        if s.get("type") == kind:
            return s
    return None


def mask_fields(robot: dict, allow_python: bool = False) -> list[Field]:
    """The panel's fields for ``robot`` (a robot entry of a scenario, as a dict)."""
    model = robot.get("model", "differential")
    cls = MODELS[model]
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
    for f in dc_fields(cls):
        v = params.get(f.name, f.default)
        if isinstance(f.default, str):
            opts = ("ackermann", "parallel") if f.name == "steering_geometry" else (str(v),)
            out.append(Field(f"params.{f.name}", plain_label(f.name), "dropdown", v, opts))
        else:
            label = plain_label(f.name)
            out.append(Field(f"params.{f.name}", label, "number", float(v), step=0.01))
    out += [
        Field("body.length_m", "body length (m)", "number", body.get("length_m", 0.6)),
        Field("body.width_m", "body width (m)", "number", body.get("width_m", 0.45)),
        Field("pose.x_m", "initial x (m)", "number", pose.get("x_m", 0.0), step=0.1),
        Field("pose.y_m", "initial y (m)", "number", pose.get("y_m", 0.0), step=0.1),
        Field(
            "pose.theta_deg",
            "initial heading (deg)",
            "number",
            pose.get("theta_deg", 0.0),
            step=1.0,
        ),
    ]
    for kind, items in SENSOR_FIELDS.items():
        s = _sensor(robot, kind)
        out.append(Field(f"sensors.{kind}", f"{kind} on", "checkbox", s is not None))
        for key, label, fk, default in items:
            v = _default(robot, key, default) if s is None or s.get(key) is None else s[key]
            out.append(Field(f"sensors.{kind}.{key}", f"{kind} {label}", fk, v))
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
    return out


class MaskError(ValueError):
    """A field the panel cannot even turn into a scenario entry (e.g. unreadable YAML)."""


def robot_from_mask(robot: dict, values: dict[str, Any]) -> dict:
    """A copy of ``robot`` with the panel's ``values`` (field key -> value) written in."""
    out = copy.deepcopy(robot)
    model_changed = "model" in values and values["model"] != robot.get("model")
    for key in ("name", "model", "mode"):
        if key in values:
            out[key] = values[key]
    if model_changed:  # the old model's parameters mean nothing to the new one
        out["params"] = {}
    names = {f.name: f.default for f in dc_fields(MODELS[out["model"]])}
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
        for key, _label, fk, default in SENSOR_FIELDS[kind]:
            v = values.get(f"sensors.{kind}.{key}")
            # keys the entry leaves unset stay unset while the panel shows their default
            if v is not None and (key in s or v != _default(robot, key, default)):
                s[key] = int(round(v)) if fk == "int" else v
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
