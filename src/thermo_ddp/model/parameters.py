"""Motor and thermal parameter files (TOML, ``models/<joint>.toml``): load, validate, write.

The file format is a contract (docs/architecture.md): SI units, the unit in each key's name.
"""
from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import tomli_w

from ..errors import InputError
from .catalogue import (BOUNDS, HEAT_SOURCE_KINDS, NETWORK_MODEL, SOURCE_KINDS, THERMAL_KEYS, THERMAL_MODELS,  # noqa: F401
                        THERMAL_NODE_CHOICES, THERMAL_OPTIONAL, Bound, checked_value, unit)
from .network_spec import NetworkSpec, general_network, read_network
from .scope import Scope, read_alternatives, read_covariance, read_envelope, read_hardware, read_uncertainty

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
    """Lumped thermal network parameters.  A legacy model (``one_node``, ``two_node``, ``two_node_drive``):
    ``values`` holds the model's keys (:data:`THERMAL_KEYS`) and the optional ones given
    (:data:`THERMAL_OPTIONAL`; absent ones read as their defaults), ``sensor`` and ``friction_heat_node``
    the optional node choices (None: absent, see :data:`THERMAL_NODE_CHOICES`).  A general network
    (``model = "network"``): ``network`` holds nodes, links and sources, ``sensor`` names a node, ``room_c``
    the room's temperature for links to ``"room"`` when a recording gives none (None: absent, the ambient's).
    Values may be CasADi symbols (identification)."""

    model: str
    ambient_c: float
    values: Mapping[str, float] = field(default_factory=dict)
    sensor: str | None = None
    friction_heat_node: str | None = None
    network: NetworkSpec | None = None
    room_c: float | None = None

    def __getitem__(self, key: str) -> float:
        if self.network is not None:
            raise KeyError(f"{key}: a general network has no legacy [thermal] keys (see paths())")
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

    @property
    def general(self) -> NetworkSpec:
        """The network in the general form (a legacy model through :func:`general_network`)."""
        return self.network if self.network is not None else general_network(self)

    def paths(self) -> dict[str, object]:
        """Every value of the section by its dotted path below ``thermal.``."""
        inner = self.network.paths() if self.network is not None else dict(self.values)
        return {"ambient_c": self.ambient_c, **inner}

    def with_values(self, values: Mapping[str, object]) -> "ThermalParameters":
        """A copy with the values at dotted paths below ``thermal.`` replaced, unchecked (symbols allowed):
        a legacy model's keys, or a network's paths (:meth:`NetworkSpec.with_values`)."""
        values = dict(values)
        ambient = values.pop("ambient_c", self.ambient_c)
        if self.network is not None:
            return dataclasses.replace(self, ambient_c=ambient, network=self.network.with_values(values))
        for key in values:
            if key not in THERMAL_KEYS[self.model] and key not in THERMAL_OPTIONAL:
                raise KeyError(key)
        return dataclasses.replace(self, ambient_c=ambient, values={**self.values, **values})

    def to_dict(self) -> dict[str, Any]:
        """The [thermal] section: model, ambient, the node choices and values given (or the network)."""
        choices = {k: getattr(self, k) for k in THERMAL_NODE_CHOICES if getattr(self, k) is not None}
        inner = self.network.to_dict() if self.network is not None else self.values
        room = {} if self.room_c is None else {"room_c": self.room_c}
        return {"model": self.model, "ambient_c": self.ambient_c, **room, **choices, **inner}


@dataclass(frozen=True)
class Limits:
    winding_max_c: float
    safety_cutoff_c: float


MOTOR_KEYS = tuple(f.name for f in dataclasses.fields(MotorParameters))
LIMIT_KEYS = tuple(f.name for f in dataclasses.fields(Limits))
_PLAIN_SECTIONS = {"motor": MOTOR_KEYS, "limits": LIMIT_KEYS}


@dataclass(frozen=True)
class JointParameters:
    """One parameter file: the joint's motor, thermal network, limits and sources, and its scope (what
    the motor can have, the uncertainty of its values, where they hold, alternatives: :class:`Scope`)."""

    joint: str
    motor: MotorParameters
    thermal: ThermalParameters
    limits: Limits
    sources: Mapping[str, str] = field(default_factory=dict)
    path: str = "<memory>"
    scope: Scope = field(default_factory=Scope)

    def to_dict(self) -> dict[str, Any]:
        """The file's sections as used (plan JSON ``model.motors[joint]``)."""
        return {
            "joint": {"name": self.joint},
            "motor": dataclasses.asdict(self.motor),
            "thermal": self.thermal.to_dict(),
            "limits": dataclasses.asdict(self.limits),
            "sources": dict(self.sources),
            **self.scope.to_dict(),
        }

    def paths(self) -> dict[str, object]:
        """Every value of the file by its dotted path (``motor.resistance_ohm``, ``thermal.<...>``, ``limits.<...>``)."""
        out = {f"{section}.{k}": getattr(getattr(self, section), k) for section, keys in _PLAIN_SECTIONS.items()
               for k in keys}
        return out | {f"thermal.{k}": v for k, v in self.thermal.paths().items()}

    def value(self, path: str):
        """The value at a dotted path; KeyError when the file has none there."""
        section, _, tail = path.partition(".")
        if section == "thermal" and self.thermal.network is not None and tail != "ambient_c":
            return self.thermal.network.value(tail)
        return self.paths()[path]

    def with_values(self, values: Mapping[str, object]) -> "JointParameters":
        """A copy with the values at dotted paths replaced, unchecked (CasADi symbols allowed: identification
        differentiates the same expressions); :meth:`checked` validates a numeric result.  KeyError names
        a path that fits nothing."""
        thermal = {p[len("thermal."):]: v for p, v in values.items() if p.startswith("thermal.")}
        out = dataclasses.replace(self, thermal=self.thermal.with_values(thermal) if thermal else self.thermal)
        for section, keys in _PLAIN_SECTIONS.items():
            given = {p.split(".", 1)[1]: v for p, v in values.items() if p.split(".", 1)[0] == section}
            for key in given:
                if key not in keys:
                    raise KeyError(f"{section}.{key}")
            if given:
                out = dataclasses.replace(out, **{section: dataclasses.replace(getattr(out, section), **given)})
        rest = [p for p in values if p.split(".", 1)[0] not in ("thermal", *_PLAIN_SECTIONS)]
        if rest:
            raise KeyError(rest[0])
        return out

    def checked(self, source: str | None = None) -> "JointParameters":
        """This file validated as if read (InputError naming ``source``, by default its path)."""
        return dataclasses.replace(parameters_from_dict(self.to_dict(), source or self.path), path=self.path)

    def with_scope(self, **sections) -> "JointParameters":
        """A copy with sections of its :class:`Scope` replaced (``heat_sources``, ``uncertainty``, ``covariance``,
        ``envelope``, ``alternatives``: what identify and diagnose write), validated as if read."""
        return dataclasses.replace(self, scope=dataclasses.replace(self.scope, **sections)).checked()

    def alternative(self, index: int) -> "JointParameters":
        """The file with alternative ``index``'s values (validated when the file was read); no alternatives."""
        alt = self.scope.alternatives[index]
        return dataclasses.replace(self.with_values(alt.values), scope=dataclasses.replace(self.scope, alternatives=()))

    def replace(self, section: str, **values: float) -> "JointParameters":
        """A copy with some values of ``motor``, ``thermal`` or ``limits`` replaced (validated); a replaced
        value's [uncertainty] interval (and its [covariance] row) described the value it replaces and is dropped."""
        data = self.to_dict()
        if "uncertainty" in data:
            data["uncertainty"] = {k: v for k, v in data["uncertainty"].items()
                                   if k not in {f"{section}.{key}" for key in values}}
            kept = self.scope.covariance and self.scope.covariance.restricted(data["uncertainty"])
            data.pop("covariance", None)
            if kept:
                data["covariance"] = kept.to_dict()
        known = set(data[section]) | (set(THERMAL_OPTIONAL) | set(THERMAL_NODE_CHOICES) if section == "thermal" else set())
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(self.path, f"{section}.{unknown[0]}", values[unknown[0]], "unknown key")
        data[section].update(values)
        return parameters_from_dict(data, self.path)


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
    if model not in (*THERMAL_MODELS, NETWORK_MODEL):
        raise InputError(source, "thermal.model", repr(model), f"expected one of {', '.join(THERMAL_MODELS)}, {NETWORK_MODEL}")
    if "ambient_c" not in sec:
        raise InputError(source, "thermal.ambient_c", "<missing>", "required key missing")
    ambient = checked_value(source, "thermal.ambient_c", "ambient_c", sec["ambient_c"])
    if model == NETWORK_MODEL:
        return _network_thermal(source, sec, ambient)
    required = THERMAL_KEYS[model]
    optional = tuple(k for k in THERMAL_OPTIONAL if k not in required)
    values = _read_keys(source, sec, "thermal", required, optional,
                        ignore=("model", "ambient_c", *THERMAL_NODE_CHOICES))
    return ThermalParameters(model, ambient, values, *(_node_choice(source, sec, k, model) for k in THERMAL_NODE_CHOICES))


def _network_thermal(source: str, sec: Mapping[str, Any], ambient_c: float) -> ThermalParameters:
    """A ``model = "network"`` section: its tables (:func:`read_network`) and the ``sensor`` node (required)."""
    for key in sec:
        if key not in ("model", "ambient_c", "room_c", "sensor", "node", "link", "source"):
            raise InputError(source, f"thermal.{key}", sec[key], "unknown key of a network (its heat is in "
                             "[[thermal.source]], its nodes in [[thermal.node]], its links in [[thermal.link]])")
    network = read_network(source, sec)
    sensor = sec.get("sensor", "<missing>")
    if sensor not in network.node_names:
        raise InputError(source, "thermal.sensor", repr(sensor), "name the node the recording's temperature_c "
                         f"measures, one of {', '.join(network.node_names)}")
    room = checked_value(source, "thermal.room_c", "room_c", sec["room_c"]) if "room_c" in sec else None
    return ThermalParameters(NETWORK_MODEL, ambient_c, {}, sensor, network=network, room_c=room)


def _sources_text(source: str, data: Mapping[str, Any]) -> dict[str, str]:
    sources = data.get("sources", {})
    if not isinstance(sources, Mapping):
        raise InputError(source, "[sources]", repr(sources), "expected key = \"free text\" lines")
    for key, text in sources.items():
        if not isinstance(text, str):
            raise InputError(source, f"sources.{key}", repr(text), "expected \"free text\": where the value comes from")
    return dict(sources)


def _scope(source: str, data: Mapping[str, Any], core: JointParameters) -> Scope:
    """[hardware] (every heat source of the network must be allowed), [uncertainty], [envelope],
    [[alternatives]] (each, applied to the file, must give a valid file of this motor)."""
    hardware = read_hardware(source, data)
    allowed = Scope(hardware).allowed_sources
    for src in core.thermal.general.sources:
        if src.kind not in allowed:
            raise InputError(source, "hardware.heat_sources", repr(list(allowed)), f"the [thermal] section has "
                             f"{src.kind} heat ({src.label}), which this list says the motor cannot have")
    scoped = dataclasses.replace(core, scope=Scope(hardware))

    def check(where: str, values: Mapping[str, float]) -> None:
        try:
            candidate = scoped.with_values(values)
        except KeyError as err:
            raise InputError(source, where, err.args[0], "names no value this file can hold") from None
        candidate.checked(f"{source} {where}")

    uncertainty = read_uncertainty(source, data, core.value)
    return Scope(hardware, uncertainty, read_envelope(source, data), read_alternatives(source, data, check),
                 read_covariance(source, data, uncertainty, core.value))


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
    core = JointParameters(joint, motor, thermal, limits, _sources_text(source, data), source)
    return dataclasses.replace(core, scope=_scope(source, data, core))


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
