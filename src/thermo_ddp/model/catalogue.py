"""The parameter file's key catalogue: every key of the contract with its physically possible range
(:class:`Bound`), the thermal models' keys and defaults, the heat-source kinds of a general network and
their values, and the envelope's quantities.  One home for each range check and key list.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

THERMAL_MODELS = ("one_node", "two_node", "two_node_drive")  # the legacy models, with their own keys
NETWORK_MODEL = "network"  # a general network: [[thermal.node]], [[thermal.link]], [[thermal.source]]

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
    "iron_loss_speed_exponent": Bound(1.0, 2.5, "", "hysteresis ~ speed (1), eddy currents ~ speed^2 (2), "
                                      "skin effect and excess losses between; IEC 60404-8 fits stay below 2.5"),
    "constant_heat_w": _HEAT_W,
    "ac_copper_factor": Bound(0.0, 10.0, "", "AC over DC copper loss at the reference speed: skin and proximity "
                              "effects of traction windings reach ~0.1-1 at rated frequency, not 10"),
    "ac_copper_ref_speed_rad_s": Bound(1e-3, 1e4, "rad/s", "a joint speed"),
    "room_c": _CELSIUS,
    "share": Bound(0.0, 1.0, "", "the part of a source's heat that enters one node"),
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




# --- a general network ([thermal] model = "network") ------------------------------------------------
# Heat-source kinds and their values: kind -> {value key in [[thermal.source]]: catalogue key (its
# bound and default, THERMAL_OPTIONAL, are the legacy key's)}.  Powers, written in model/thermal.py:
#   copper            R(T_w) i^2 of [motor] (eq. 5)
#   iron_losses       power_w (|w| / ref_speed_rad_s)^speed_exponent
#   friction_heating  linear_w_s_per_rad |w| + quadratic_w_s2_per_rad2 w^2 + motor_fraction tau_f(w) w
#   drive_heating     idle_w + loss_w_per_a2 i^2
#   constant          power_w
#   ac_copper         factor R(T_w) i^2 (|w| / ref_speed_rad_s)^2 (skin and proximity effects in the copper)
SOURCE_KINDS: dict[str, dict[str, str]] = {
    "copper": {},
    "iron_losses": {"power_w": "iron_loss_w", "ref_speed_rad_s": "iron_loss_ref_speed_rad_s",
                    "speed_exponent": "iron_loss_speed_exponent"},
    "friction_heating": {"linear_w_s_per_rad": "friction_heat_linear_w_s_per_rad",
                         "quadratic_w_s2_per_rad2": "friction_heat_quadratic_w_s2_per_rad2",
                         "motor_fraction": "friction_heating_fraction"},
    "drive_heating": {"idle_w": "drive_idle_w", "loss_w_per_a2": "drive_loss_w_per_a2"},
    "constant": {"power_w": "constant_heat_w"},
    "ac_copper": {"factor": "ac_copper_factor", "ref_speed_rad_s": "ac_copper_ref_speed_rad_s"},
}
HEAT_SOURCE_KINDS = tuple(SOURCE_KINDS)
# source values without a legacy [thermal] key
_SOURCE_ONLY_DEFAULTS = {"constant_heat_w": 0.0, "ac_copper_factor": 0.0, "ac_copper_ref_speed_rad_s": 1.0}
NETWORK_KEYS = ("share", "room_c", *_SOURCE_ONLY_DEFAULTS)   # catalogue keys only a general network uses
SHARE_SUM_TOLERANCE = 1e-6  # the shares of one source's split sum to 1 within this
LIMIT_NODE = "winding"      # the node the winding limit applies to: every network has it

# [envelope]: the operating range a file was identified on (magnitudes of current and speed).
ENVELOPE_QUANTITIES: dict[str, str] = {"current_a": "A", "speed_rad_s": "rad/s", "ambient_c": "°C",
                                       "temperature_c": "°C", "room_c": "°C"}


def source_value_default(kind: str, key: str) -> float:
    """The default of a source value (the catalogue key's, :data:`THERMAL_OPTIONAL`)."""
    key = SOURCE_KINDS[kind][key]
    return THERMAL_OPTIONAL[key] if key in THERMAL_OPTIONAL else _SOURCE_ONLY_DEFAULTS[key]
