"""The thermal diagnosis's candidate terms: their physical ranges, the parameter-file keys each decides, the
experiment that separates each from what it can be confused with, and the rule of the held-out judgement."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..identify.thermal import FRICTION_KEYS, IRON_KEY, SENSOR_DRIVE_KEYS, THERMAL_TERMS, JointParameters
from ..model.parameters import THERMAL_KEYS
from .selection import TermSpec

CANDIDATE_TERMS = THERMAL_TERMS
# Iron-loss bound: at the no-load speed V_bus / (K_b N) (joint side) the iron losses are at most half
# the no-load power V_bus * I_0, with I_0 ~ 0.1 A for 48 V maxon EC-flat/EC-4pole motors of this class
# (datasheets list no-load currents of 0.05-0.3 A; the no-load power also covers bearing friction).
NO_LOAD_CURRENT_A = 0.1
IRON_SHARE_OF_NO_LOAD = 0.5
# Larger motors: a no-load current of 2 % of the rated current (the 0.1 A of a 5 A maxon; traction machines
# lose 1-3 % of their rated power unloaded at rated speed).
NO_LOAD_CURRENT_SHARE = 0.02
# A drive idles at up to 100 W in the Talos class (the elbow's 23 W, report), or at up to 5 times the motor's
# rated copper loss R I_nom^2 for larger drives.
DRIVE_IDLE_SHARE = 5.0
# Speeds: a joint turning slower than this is at rest; moving samples whose speeds lie within this factor
# (5th to 95th percentile) are one speed; a motor moving in this share of the samples never rests.
MOVING_RAD_S = 0.05
ONE_SPEED_SPREAD = 1.25
ALWAYS_MOVING = 0.9
SPEED_TERMS = ("friction_heating", "iron_losses")
# Ranges of capacities and resistances also hold the parameter file's own value within this factor.
FILE_VALUE_FACTOR = 10.0
# The experiment that separates each term from what it can be confused with, worded from the motor's own
# recorded range (:func:`experiments`): speeds and currents as shares of the 95th percentiles it reached.


def recorded_range(grids: Sequence, params: JointParameters) -> tuple[float, float]:
    """(speed rad/s, current A): the 95th percentiles of the recorded moving speed and of the current; without
    recorded motion (or current) a quarter of the file's no-load speed V_bus / (K_b N) (its rated current)."""
    speeds = np.abs(np.concatenate([g.velocity for g in grids if g.has_velocity] or [np.zeros(0)]))
    moving = speeds[speeds > MOVING_RAD_S]
    m = params.motor
    speed = (float(np.percentile(moving, 95)) if moving.size else
             0.25 * m.bus_voltage_v / (m.back_emf_v_s_per_rad * m.gear_ratio))
    currents = np.abs(np.concatenate([g.current_a for g in grids] or [np.zeros(0)]))
    current = float(np.percentile(currents, 95)) if currents.size and np.any(currents > 0) else m.current_nominal_a
    return speed, current


def experiments(grids: Sequence, params: JointParameters) -> dict[str, str]:
    """The experiment that separates each candidate term, at this motor's own speeds and currents
    (:func:`recorded_range`); a gearbox is mentioned only for a geared joint (gear ratio above 1)."""
    w, i = recorded_range(grids, params)
    geared = params.motor.gear_ratio > 1
    return {
        "friction_heating": f"move at two speeds (e.g. {0.25 * w:.3g} and {w:.3g} rad/s, 20 min each) with a light "
                            f"load, and hold the same current still for 20 min next to it",
        "iron_losses": f"turn with the current near zero at {w:.3g} rad/s for 10 min"
                       + (" (gearbox disengaged if possible)" if geared else "") + f", then at {0.5 * w:.3g} rad/s: "
                       "iron losses grow with the speed to a power 1-2.5"
                       + (", gearbox friction about linearly" if geared else ", bearing friction about linearly"),
        "drive_heating": "leave the motor powered and idle (current near zero) for 1 h, then switch the drive off "
                         "and record the cooling for 1 h",
        "casing_node": f"current steps (e.g. {0.8 * i:.3g} A for 30 s, 150 s apart) with the motor voltage logged: "
                       "the winding resistance shows the fast winding node the casing sensor smooths out",
        "copper_resistance": f"hold two currents (e.g. {0.4 * i:.3g} A and {0.8 * i:.3g} A) until steady with the "
                             "motor voltage logged",
    }


def beyond_envelope(envelope) -> tuple[str, str]:
    """(the recordings that would pin down what these could not, two speeds to try) worded from the operating
    range the recordings covered (``envelope``: :func:`~thermo_ddp.envelope.envelope_of`); without it, in general."""
    ranged = {"speed_rad_s", "current_a", "ambient_c"} <= set(envelope)
    beyond = "recordings at other speeds, currents and ambient (coolant) temperatures than these" + (
        f" (speed up to {envelope['speed_rad_s'][1]:.3g} rad/s, current up to {envelope['current_a'][1]:.3g} A, "
        f"ambient_c {envelope['ambient_c'][0]:.3g}-{envelope['ambient_c'][1]:.3g} °C)" if ranged else "")
    top = envelope["speed_rad_s"][1] if "speed_rad_s" in envelope else 0.0
    return beyond, (f" (e.g. {0.4 * top:.3g} and {top:.3g} rad/s)" if top > 0 else "")


def room_note(texts: dict[str, str]) -> dict:
    """Without a room thermometer a steady heat on the sensor node and a room warmer than the file's
    ambient_c are one and the same (exactly so for one node): the drive heat is then fitted in every model
    as the room's stand-in, never tested, never named."""
    return {"term": "drive_heating",
            "reason": "no recording logs the room (ambient_c): a steady heat on the sensor node reads the same as a "
                      "room warmer than the parameter file's ambient_c; fitted in every model as the room's stand-in, "
                      "not named",
            "experiment": "log the room temperature (ambient_c) beside the motor; " + texts["drive_heating"]}


# How a term is judged leaving one segment out (diagnosis JSON and report).
HELD_OUT_RULE = ("each segment (recording or stretch between gaps) predicted from its first measurement by a fit of "
                 "the other segments; a chosen term is judged on the segments that can judge it: the others hold more "
                 "samples, reach its speeds and hold every operating regime it spends time in (at rest, loaded at "
                 "rest, moving), and, when either network has a node besides the sensor, it starts at thermal rest "
                 "(the prediction starts from the network's equilibrium); a term whose pooled held-out RMSE there is "
                 "higher with it than without, by more than the noise of one reading, is withdrawn; a tie, or no "
                 "segment able to judge, is no evidence against it: it stands on the in-sample test and "
                 "not_determinable says so; validation: the segments every chosen term was judged on")
_CASING_KEYS = ("winding_capacity_j_per_k", "casing_capacity_j_per_k", "winding_casing_k_per_w", "casing_ambient_k_per_w")


def iron_max(params: JointParameters) -> float:
    """Largest physical iron-loss coefficient k [W s^2/rad^2] (joint-side speed), see the constants above."""
    m = params.motor
    no_load_speed = m.bus_voltage_v / (m.back_emf_v_s_per_rad * m.gear_ratio)
    no_load_current = max(NO_LOAD_CURRENT_A, NO_LOAD_CURRENT_SHARE * m.current_nominal_a)
    return IRON_SHARE_OF_NO_LOAD * m.bus_voltage_v * no_load_current / no_load_speed ** 2


def _around_file(params: JointParameters, key: str, low: float, high: float) -> tuple[float, float]:
    """(low, high) widened to hold the parameter file's own value within ``FILE_VALUE_FACTOR`` both ways:
    the class ranges below are the Talos joints'; a file of another motor (a traction machine, a UR3 joint)
    brings its own scale."""
    value = params.thermal.values.get(key)
    if value is None or not value > 0:
        return low, high
    return min(low, value / FILE_VALUE_FACTOR), max(high, value * FILE_VALUE_FACTOR)


def term_specs(params: JointParameters) -> dict[str, TermSpec]:
    """Physical ranges of every term's parameters (inclusive).  Capacities: 0.1-20 kg of aluminium or
    copper (385-900 J/kg/K); resistances: maxon class data, winding-housing 0.5-5 K/W and
    housing-ambient 1-10 K/W, widened; both also hold the file's own values (another motor's scale);
    copper alpha: 0.00393 /K (report eq. 3) +-10 %; heat >= 0 (friction heat is free: no bound from the
    file's friction); drive idle heat and iron losses bounded by the motor's rating (constants above)."""
    def scaled(ranges: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        return {key: _around_file(params, key, *bounds) for key, bounds in ranges.items()}

    m = params.motor
    drive_idle_max_w = max(100.0, DRIVE_IDLE_SHARE * m.resistance_ohm * m.current_nominal_a ** 2)
    casing = scaled({"winding_capacity_j_per_k": (1.0, 1000.0), "casing_capacity_j_per_k": (100.0, 2e4),
                     "winding_casing_k_per_w": (0.05, 10.0), "casing_ambient_k_per_w": (0.1, 20.0)})
    return {
        "one_node": TermSpec("one_node", scaled({"capacity_j_per_k": (100.0, 2e4), "resistance_k_per_w": (0.1, 20.0)})),
        "casing_node": TermSpec("casing_node", casing),
        "drive_heating": TermSpec("drive_heating", {"drive_capacity_j_per_k": (10.0, 1e4),
                                                    "drive_casing_k_per_w": (0.02, 50.0),
                                                    "drive_idle_w": (0.0, drive_idle_max_w),
                                                    "drive_loss_w_per_a2": (0.0, 5.0)}),
        "friction_heating": TermSpec("friction_heating", {k: (0.0, math.inf) for k in FRICTION_KEYS}),
        "copper_resistance": TermSpec("copper_resistance", {"copper_alpha_per_k": (0.0035, 0.0045)}),
        "iron_losses": TermSpec("iron_losses", {IRON_KEY: (0.0, iron_max(params))}),
    }


def term_keys(term: str, terms: Sequence[str]) -> tuple[str, ...]:
    """The parameter-file keys ``term`` decides in the structure ``terms``."""
    if term == "drive_heating":
        return THERMAL_KEYS["two_node_drive"][4:] if "casing_node" in terms else SENSOR_DRIVE_KEYS
    return {"friction_heating": FRICTION_KEYS, "copper_resistance": ("copper_alpha_per_k",),
            "iron_losses": (IRON_KEY,), "casing_node": _CASING_KEYS}[term]

