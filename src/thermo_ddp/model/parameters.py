"""Motor and thermal parameter files (TOML, ``models/<joint>.toml``): load, validate, write.

The file format is a contract (docs/architecture.md): SI units, the unit in each key's name.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import tomli_w

from ..errors import InputError

THERMAL_MODELS = ("one_node", "two_node", "two_node_drive")

# --- the key catalogue: every motor, thermal and limit key of the contract, with its check ----------
@dataclass(frozen=True)
class Bound:
    """Physically possible values of one key: ``low <= x <= high`` in ``unit``, and why.

    The sign rule follows ``low``: > 0 keys (``low > 0``) refuse zero, >= 0 keys (``low == 0``) refuse
    negatives, temperatures (``low < 0``) only the range."""

    low: float
    high: float
    unit: str
    reason: str

    def check(self, source: str, name: str, value: Any, what: str = "physically impossible") -> float:
        """``value`` as a finite float of the right sign within the bound (numpy scalars accepted);
        InputError naming ``source``, ``name``, the value, the range, its unit and ``reason`` otherwise."""
        x = _number(source, name, value)
        unit = f" {self.unit}" if self.unit else ""
        if self.low > 0 and x <= 0:
            raise InputError(source, name, x, f"must be > 0{unit}")
        if self.low == 0 and x < 0:
            raise InputError(source, name, x, f"must be >= 0{unit}")
        if not self.low <= x <= self.high:
            raise InputError(source, name, x, f"{what}: expected {self.low:g} to {self.high:g}{unit} ({self.reason})")
        return x


_RESISTANCE_K_PER_W = Bound(1e-4, 1e4, "K/W", "a liquid-cooled housing ~0.01, a tiny part in still air ~1000")
_CAPACITY_J_PER_K = Bound(1e-3, 1e7, "J/K", "a milligram of copper to ten tonnes of steel")
_HEAT_W = Bound(0.0, 1e5, "W", "heat is non-negative; 100 kW is beyond any joint motor")
_CELSIUS = Bound(-50.0, 80.0, "°C", "contract: rooms and machines between -50 and 80 °C")
_HOT_CELSIUS = Bound(-50.0, 400.0, "°C", "above ambient; no winding insulation survives 400 °C")

BOUNDS: dict[str, Bound] = {
    # [motor]
    "gear_ratio": Bound(0.01, 1e4, "", "direct drive is 1, strain-wave gears ~160, worm stages ~1e3"),
    "torque_constant_nm_per_a": Bound(1e-4, 100.0, "N·m/A", "micro motors ~1e-3, large torque motors ~10"),
    "back_emf_v_s_per_rad": Bound(1e-4, 100.0, "V·s/rad", "equals the torque constant in SI units"),
    "resistance_ohm": Bound(1e-4, 1e3, "ohm", "large motors ~1 mohm, micro motors ~100 ohm"),
    "resistance_ref_c": Bound(-50.0, 200.0, "°C", "datasheets quote 20-25 °C"),
    "copper_alpha_per_k": Bound(0.0, 0.02, "1/K", "copper 0.00393, no conductor above 0.007; 0 disables R(T)"),
    "rotor_inertia_kg_m2": Bound(1e-10, 1.0, "kg·m^2", "micro rotors ~1e-8, large servo rotors ~1e-2"),
    "viscous_friction_nm_s_per_rad": Bound(0.0, 1e4, "N·m·s/rad", "dissipative: non-negative"),
    "coulomb_friction_nm": Bound(0.0, 1e4, "N·m", "dissipative: non-negative"),
    "coulomb_smoothing_rad_s": Bound(1e-6, 10.0, "rad/s", "a smoothing of sign(v), well below joint speeds"),
    "bus_voltage_v": Bound(1.0, 1e4, "V", "from single cells to industrial drives"),
    "current_nominal_a": Bound(1e-4, 1e4, "A", "micro motors ~10 mA, traction motors ~1 kA"),
    "current_peak_a": Bound(1e-4, 1e4, "A", "micro motors ~10 mA, traction motors ~1 kA"),
    # [thermal]
    "ambient_c": _CELSIUS,
    "capacity_j_per_k": _CAPACITY_J_PER_K, "winding_capacity_j_per_k": _CAPACITY_J_PER_K,
    "casing_capacity_j_per_k": _CAPACITY_J_PER_K, "drive_capacity_j_per_k": _CAPACITY_J_PER_K,
    "resistance_k_per_w": _RESISTANCE_K_PER_W, "winding_casing_k_per_w": _RESISTANCE_K_PER_W,
    "casing_ambient_k_per_w": _RESISTANCE_K_PER_W, "drive_casing_k_per_w": _RESISTANCE_K_PER_W,
    "drive_ambient_k_per_w": _RESISTANCE_K_PER_W,
    "drive_idle_w": _HEAT_W,
    "drive_loss_w_per_a2": Bound(0.0, 100.0, "W/A^2", "a resistance of the drive: non-negative, < 100 ohm"),
    "friction_heating_fraction": Bound(0.0, 1.0, "", "a share of the friction power"),
    "friction_heat_linear_w_s_per_rad": Bound(0.0, 1e5, "W·s/rad", "heat is non-negative"),
    "friction_heat_quadratic_w_s2_per_rad2": Bound(0.0, 1e5, "W·s^2/rad^2", "heat is non-negative"),
    "iron_loss_w": _HEAT_W,
    "iron_loss_ref_speed_rad_s": Bound(1e-3, 1e4, "rad/s", "a joint speed"),
    "iron_loss_speed_exponent": Bound(1.0, 3.0, "", "hysteresis ~ speed (1), eddy currents ~ speed^2 (2)"),
    # [limits]
    "winding_max_c": _HOT_CELSIUS,
    "safety_cutoff_c": _HOT_CELSIUS,
}

THERMAL_KEYS: dict[str, tuple[str, ...]] = {
    "one_node": ("capacity_j_per_k", "resistance_k_per_w"),
    "two_node": ("winding_capacity_j_per_k", "casing_capacity_j_per_k",
                 "winding_casing_k_per_w", "casing_ambient_k_per_w"),
}
THERMAL_KEYS["two_node_drive"] = THERMAL_KEYS["two_node"] + (
    "drive_capacity_j_per_k", "drive_casing_k_per_w", "drive_ambient_k_per_w",
    "drive_idle_w", "drive_loss_w_per_a2")
# Optional numeric [thermal] keys, valid with any model, and their defaults (contract, plus the
# pre-contract ``friction_heating_fraction``). A model's own key is required, not optional.
THERMAL_OPTIONAL: dict[str, float] = {
    "friction_heating_fraction": 0.0,
    "friction_heat_linear_w_s_per_rad": 0.0, "friction_heat_quadratic_w_s2_per_rad2": 0.0,
    "iron_loss_w": 0.0, "iron_loss_ref_speed_rad_s": 1.0, "iron_loss_speed_exponent": 2.0,
    "drive_idle_w": 0.0, "drive_loss_w_per_a2": 0.0,
}
# Optional node choices of [thermal]: key -> (allowed nodes, default).
THERMAL_NODE_CHOICES: dict[str, tuple[tuple[str, ...], str]] = {
    "sensor": (("casing", "winding"), "casing"),
    "friction_heat_node": (("winding", "casing"), "winding"),
}


def unit(key: str) -> str:
    """The unit of a catalogue key (``"J/K"`` for ``casing_capacity_j_per_k``)."""
    return BOUNDS[key].unit


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
    """Lumped thermal network parameters: ``values`` holds the model's keys (:data:`THERMAL_KEYS`) and
    the optional ones given (:data:`THERMAL_OPTIONAL`; absent ones read as their defaults); values may
    be CasADi symbols (identification). ``sensor`` and ``friction_heat_node`` are the optional node
    choices (None: absent, see :data:`THERMAL_NODE_CHOICES`)."""

    model: str
    ambient_c: float
    values: Mapping[str, float]
    sensor: str | None = None
    friction_heat_node: str | None = None

    def __getitem__(self, key: str) -> float:
        if key in self.values:
            return self.values[key]
        return THERMAL_OPTIONAL[key]

    @property
    def sensor_node(self) -> str:
        """The measured node: ``sensor``, by default the casing (the winding of a one-node network)."""
        return self.sensor or ("winding" if self.model == "one_node" else THERMAL_NODE_CHOICES["sensor"][1])

    @property
    def friction_node(self) -> str:
        """Where the contract's friction heat enters: ``friction_heat_node``, by default the winding."""
        return self.friction_heat_node or THERMAL_NODE_CHOICES["friction_heat_node"][1]

    def to_dict(self) -> dict[str, Any]:
        """The [thermal] section: model, ambient, the node choices and values given."""
        choices = {k: getattr(self, k) for k in THERMAL_NODE_CHOICES if getattr(self, k) is not None}
        return {"model": self.model, "ambient_c": self.ambient_c, **choices, **self.values}


@dataclass(frozen=True)
class Limits:
    winding_max_c: float
    safety_cutoff_c: float


MOTOR_KEYS = tuple(f.name for f in dataclasses.fields(MotorParameters))
LIMIT_KEYS = tuple(f.name for f in dataclasses.fields(Limits))


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
            "thermal": self.thermal.to_dict(),
            "limits": dataclasses.asdict(self.limits),
            "sources": dict(self.sources),
        }

    def replace(self, section: str, **values: float) -> "JointParameters":
        """A copy with some values of ``motor``, ``thermal`` or ``limits`` replaced (validated)."""
        data = self.to_dict()
        known = set(data[section]) | (set(THERMAL_OPTIONAL) | set(THERMAL_NODE_CHOICES) if section == "thermal" else set())
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(self.path, f"{section}.{unknown[0]}", values[unknown[0]], "unknown key")
        data[section].update(values)
        return parameters_from_dict(data, self.path)


def _number(source: str, key: str, value: Any) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise InputError(source, key, repr(value), "expected a number in the SI unit named by the key")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(source, key, value, "expected a finite number")
    return value


def checked_value(source: str, name: str, key: str, value: Any) -> float:
    """``value`` of catalogue ``key`` (shown as ``name``) as a finite number of the right sign within
    the key's :data:`BOUNDS`; InputError otherwise."""
    return BOUNDS[key].check(source, name, value)


def _above_ambient(source: str, key: str, value: float, ambient_c: float) -> None:
    if value <= ambient_c:
        raise InputError(source, key, value, f"must be above thermal.ambient_c = {ambient_c:g} °C")


def _section(source: str, data: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    sec = data.get(name)
    if not isinstance(sec, Mapping):
        raise InputError(source, f"[{name}]", "<missing>", "required section missing")
    return sec


def _read_keys(source: str, sec: Mapping[str, Any], section: str, required: tuple[str, ...],
               optional: tuple[str, ...] = (), ignore: tuple[str, ...] = ()) -> dict[str, float]:
    """The required keys and the optional ones present, checked; unknown keys are refused."""
    for key in sec:
        if key not in required and key not in optional and key not in ignore:
            raise InputError(source, f"{section}.{key}", sec[key], "unknown key (typo?)")
    out = {}
    for key in required:
        if key not in sec:
            raise InputError(source, f"{section}.{key}", "<missing>", "required key missing")
        out[key] = checked_value(source, f"{section}.{key}", key, sec[key])
    out |= {key: checked_value(source, f"{section}.{key}", key, sec[key]) for key in optional if key in sec}
    return out


def _node_choice(source: str, sec: Mapping[str, Any], key: str, model: str) -> str | None:
    """An optional node name of [thermal] (None when absent); a one-node network has only the winding."""
    if key not in sec:
        return None
    allowed = THERMAL_NODE_CHOICES[key][0]
    if model == "one_node":
        allowed = ("winding",)
    if sec[key] not in allowed:
        raise InputError(source, f"thermal.{key}", repr(sec[key]), f"expected one of {', '.join(allowed)} for {model}")
    return sec[key]


def _thermal(source: str, sec: Mapping[str, Any]) -> ThermalParameters:
    model = sec.get("model", "<missing>")
    if model not in THERMAL_MODELS:
        raise InputError(source, "thermal.model", repr(model), f"expected one of {', '.join(THERMAL_MODELS)}")
    if "ambient_c" not in sec:
        raise InputError(source, "thermal.ambient_c", "<missing>", "required key missing")
    ambient = checked_value(source, "thermal.ambient_c", "ambient_c", sec["ambient_c"])
    required = THERMAL_KEYS[model]
    optional = tuple(k for k in THERMAL_OPTIONAL if k not in required)
    values = _read_keys(source, sec, "thermal", required, optional,
                        ignore=("model", "ambient_c", *THERMAL_NODE_CHOICES))
    return ThermalParameters(model, ambient, values, *(_node_choice(source, sec, k, model) for k in THERMAL_NODE_CHOICES))


def parameters_from_dict(data: Mapping[str, Any], source: str = "<memory>") -> JointParameters:
    """Validate a parsed parameter file; errors name the file, key and value."""
    joint = _section(source, data, "joint").get("name")
    if not isinstance(joint, str) or not joint:
        raise InputError(source, "joint.name", repr(joint), "expected a joint name")
    motor = MotorParameters(**_read_keys(source, _section(source, data, "motor"), "motor", MOTOR_KEYS))
    if motor.current_peak_a < motor.current_nominal_a:
        raise InputError(source, "motor.current_peak_a", motor.current_peak_a, "must be >= current_nominal_a")
    thermal = _thermal(source, _section(source, data, "thermal"))
    limits = Limits(**_read_keys(source, _section(source, data, "limits"), "limits", LIMIT_KEYS))
    for key in LIMIT_KEYS:
        _above_ambient(source, f"limits.{key}", getattr(limits, key), thermal.ambient_c)
    sources = data.get("sources", {})
    if not isinstance(sources, Mapping):
        raise InputError(source, "[sources]", repr(sources), "expected key = \"free text\" lines")
    for key, text in sources.items():
        if not isinstance(text, str):
            raise InputError(source, f"sources.{key}", repr(text), "expected \"free text\": where the value comes from")
    return JointParameters(joint, motor, thermal, limits, dict(sources), source)


def packaged_parameter_file(name: str) -> Path:
    """The parameter file ``<name>.toml`` shipped with the package (package data ``thermo_ddp.models``, whose
    one source is the repository's top-level ``models/``)."""
    path = Path(str(resources.files("thermo_ddp.models").joinpath(f"{name}.toml")))
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
    except (OSError, UnicodeDecodeError) as exc:  # a folder, no permission, a binary file
        raise InputError(str(path), "file", str(path), f"cannot read a parameter file ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(str(path), "TOML", "<file>", f"not valid TOML ({exc})") from None
    return parameters_from_dict(data, str(path))


def dumps_parameters(params: JointParameters) -> str:
    """TOML text of a parameter set, in the contract's section order."""
    return tomli_w.dumps(params.to_dict())


def save_parameters(params: JointParameters, path: str | Path) -> None:
    """Write ``params`` as a parameter file (TOML, the contract's sections) that :func:`load_parameters` reads."""
    Path(path).write_text(dumps_parameters(params))
