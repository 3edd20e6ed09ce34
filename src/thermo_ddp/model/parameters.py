"""Motor and thermal parameter files (TOML, ``models/<joint>.toml``): load, validate, write.

The file format is a contract (docs/architecture.md): SI units, the unit in each key's name.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from ..errors import InputError

THERMAL_MODELS = ("one_node", "two_node", "two_node_drive")

_MOTOR_KEYS = (
    "gear_ratio", "torque_constant_nm_per_a", "back_emf_v_s_per_rad", "resistance_ohm",
    "resistance_ref_c", "copper_alpha_per_k", "rotor_inertia_kg_m2",
    "viscous_friction_nm_s_per_rad", "coulomb_friction_nm", "coulomb_smoothing_rad_s",
    "bus_voltage_v", "current_nominal_a", "current_peak_a",
)
# Keys that may be zero or negative (temperatures); every other number must be > 0, or >= 0 below.
_SIGNED = {"resistance_ref_c", "ambient_c", "winding_max_c", "safety_cutoff_c"}
_NON_NEGATIVE = {"viscous_friction_nm_s_per_rad", "coulomb_friction_nm", "copper_alpha_per_k",
                 "drive_idle_w", "drive_loss_w_per_a2", "friction_heating_fraction"}
_THERMAL_KEYS = {
    "one_node": ("capacity_j_per_k", "resistance_k_per_w"),
    "two_node": ("winding_capacity_j_per_k", "casing_capacity_j_per_k",
                 "winding_casing_k_per_w", "casing_ambient_k_per_w"),
}
_THERMAL_KEYS["two_node_drive"] = _THERMAL_KEYS["two_node"] + (
    "drive_capacity_j_per_k", "drive_casing_k_per_w", "drive_ambient_k_per_w",
    "drive_idle_w", "drive_loss_w_per_a2")
# Optional thermal keys with their defaults (extensions of the contract, documented there).
_THERMAL_OPTIONAL = {"friction_heating_fraction": 0.0}
_LIMIT_KEYS = ("winding_max_c", "safety_cutoff_c")


@dataclass(frozen=True)
class MotorParameters:
    """Electro-mechanics of one joint's actuator (seed report eqs. 1-5). Friction is joint side."""

    gear_ratio: float
    torque_constant_nm_per_a: float
    back_emf_v_s_per_rad: float
    resistance_ohm: float
    resistance_ref_c: float
    copper_alpha_per_k: float
    rotor_inertia_kg_m2: float
    viscous_friction_nm_s_per_rad: float
    coulomb_friction_nm: float
    coulomb_smoothing_rad_s: float
    bus_voltage_v: float
    current_nominal_a: float
    current_peak_a: float

    @property
    def armature_kg_m2(self) -> float:
        """Rotor inertia reflected to the joint, N^2 B_m."""
        return self.gear_ratio ** 2 * self.rotor_inertia_kg_m2


@dataclass(frozen=True)
class ThermalParameters:
    """Lumped thermal network parameters; ``values`` holds the model's keys (see _THERMAL_KEYS)."""

    model: str
    ambient_c: float
    values: Mapping[str, float]

    def __getitem__(self, key: str) -> float:
        return self.values[key]


@dataclass(frozen=True)
class Limits:
    winding_max_c: float
    safety_cutoff_c: float


@dataclass(frozen=True)
class JointParameters:
    """One parameter file: the joint's motor, thermal network, limits and sources."""

    joint: str
    motor: MotorParameters
    thermal: ThermalParameters
    limits: Limits
    sources: Mapping[str, str] = field(default_factory=dict)
    path: str = "<memory>"

    def to_dict(self) -> dict[str, Any]:
        """The file's sections as used (plan JSON ``model.motors[joint]``)."""
        return {
            "joint": {"name": self.joint},
            "motor": dataclasses.asdict(self.motor),
            "thermal": {"model": self.thermal.model, "ambient_c": self.thermal.ambient_c,
                        **dict(self.thermal.values)},
            "limits": dataclasses.asdict(self.limits),
            "sources": dict(self.sources),
        }

    def replace(self, section: str, **values: float) -> "JointParameters":
        """A copy with some values of ``motor``, ``thermal`` or ``limits`` replaced (validated)."""
        data = self.to_dict()
        unknown = set(values) - set(data[section])
        if section == "thermal":
            unknown -= set(_THERMAL_OPTIONAL)
        if unknown:
            raise InputError(self.path, f"{section}.{sorted(unknown)[0]}", values[sorted(unknown)[0]],
                             "unknown key")
        data[section].update(values)
        return parameters_from_dict(data, self.path)


def _number(source: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(source, key, repr(value), "expected a number in the SI unit named by the key")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(source, key, value, "expected a finite number")
    return value


def _checked(source: str, section: str, key: str, value: Any) -> float:
    name = f"{section}.{key}"
    x = _number(source, name, value)
    if key in _SIGNED:
        return x
    if key in _NON_NEGATIVE:
        if x < 0:
            raise InputError(source, name, x, "must be >= 0")
    elif x <= 0:
        raise InputError(source, name, x, "must be > 0")
    return x


def _section(source: str, data: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    sec = data.get(name)
    if not isinstance(sec, Mapping):
        raise InputError(source, f"[{name}]", "<missing>", "required section missing")
    return sec


def _read_keys(source: str, sec: Mapping[str, Any], section: str, required: tuple[str, ...],
               optional: Mapping[str, float] = {}, ignore: tuple[str, ...] = ()) -> dict[str, float]:
    for key in sec:
        if key not in required and key not in optional and key not in ignore:
            raise InputError(source, f"{section}.{key}", sec[key], "unknown key (typo?)")
    out = {}
    for key in required:
        if key not in sec:
            raise InputError(source, f"{section}.{key}", "<missing>", "required key missing")
        out[key] = _checked(source, section, key, sec[key])
    for key, default in optional.items():
        out[key] = _checked(source, section, key, sec.get(key, default))
    return out


def _thermal(source: str, sec: Mapping[str, Any]) -> ThermalParameters:
    model = sec.get("model", "<missing>")
    if model not in THERMAL_MODELS:
        raise InputError(source, "thermal.model", repr(model), f"expected one of {', '.join(THERMAL_MODELS)}")
    if "ambient_c" not in sec:
        raise InputError(source, "thermal.ambient_c", "<missing>", "required key missing")
    ambient = _checked(source, "thermal", "ambient_c", sec["ambient_c"])
    values = _read_keys(source, sec, "thermal", _THERMAL_KEYS[model], _THERMAL_OPTIONAL,
                        ignore=("model", "ambient_c"))
    if values["friction_heating_fraction"] > 1:
        raise InputError(source, "thermal.friction_heating_fraction", values["friction_heating_fraction"],
                         "must be within [0, 1]")
    return ThermalParameters(model, ambient, values)


def parameters_from_dict(data: Mapping[str, Any], source: str = "<memory>") -> JointParameters:
    """Validate a parsed parameter file; errors name the file, key and value."""
    joint = _section(source, data, "joint").get("name")
    if not isinstance(joint, str) or not joint:
        raise InputError(source, "joint.name", repr(joint), "expected a joint name")
    motor = MotorParameters(**_read_keys(source, _section(source, data, "motor"), "motor", _MOTOR_KEYS))
    if motor.current_peak_a < motor.current_nominal_a:
        raise InputError(source, "motor.current_peak_a", motor.current_peak_a, "must be >= current_nominal_a")
    limits = Limits(**_read_keys(source, _section(source, data, "limits"), "limits", _LIMIT_KEYS))
    sources = data.get("sources", {})
    if not isinstance(sources, Mapping) or not all(isinstance(v, str) for v in sources.values()):
        raise InputError(source, "[sources]", repr(sources), "expected key = \"free text\" lines")
    return JointParameters(joint, motor, _thermal(source, _section(source, data, "thermal")),
                           limits, dict(sources), source)


def packaged_parameter_file(name: str) -> Path:
    """The parameter file ``<name>.toml`` shipped with the package (``thermo_ddp/models/``)."""
    path = Path(str(resources.files("thermo_ddp").joinpath("models", f"{name}.toml")))
    if not path.is_file():
        shipped = sorted(p.stem for p in path.parent.glob("*.toml"))
        raise InputError("thermo_ddp/models", "name", name, f"no packaged parameter file; shipped: {', '.join(shipped)}")
    return path


def load_parameters(path: str | Path) -> JointParameters:
    """Read and validate ``models/<joint>.toml``."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(str(path), "file", str(path), "no such parameter file") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(str(path), "TOML", "<file>", f"not valid TOML ({exc})") from None
    return parameters_from_dict(data, str(path))


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(float(value))


def dumps_parameters(params: JointParameters) -> str:
    """TOML text of a parameter set, in the contract's section order."""
    lines = []
    for section, values in params.to_dict().items():
        lines.append(f"[{section}]")
        lines += [f"{key} = {_toml_value(val)}" for key, val in values.items()]
        lines.append("")
    return "\n".join(lines)


def save_parameters(params: JointParameters, path: str | Path) -> None:
    Path(path).write_text(dumps_parameters(params))
