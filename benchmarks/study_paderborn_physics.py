"""Why a network grown on Paderborn profiles 24 and 60 predicts the other profile badly: candidate physics,
each fitted on both profiles and left one profile out (issue 24).

A study, not a feature: written when some candidates were physics the package's networks could not express
(a second boundary temperature, a loss driven by current and speed together: now the package's terms
``room_link`` and ``ac_copper``, which the diagnosis offers), so this script integrates its own small
lumped network (trapezoidal rule on a 10 s grid of held means, copper loss R(T_w) i^2 with the packaged
file's R, T_ref and alpha, as ``model/thermal.py``).  Nothing in ``thermo_ddp`` uses it; the candidate that
helps is what a next growth term should be (docs/architecture.md, "Paderborn: what the two profiles say").

Structure common to every candidate: the three stator sensors (winding, tooth, yoke) as nodes in a chain
winding - tooth - yoke - coolant, copper heat in the winding, iron losses P (|w| / w_ref)^n (n in 1-2.5) in the
tooth.  Candidates add one thing each:

- ``chain``: nothing (the package's grown network of the previous session);
- ``room``: a link from the yoke to the test-bench room (the recordings' ``ambient`` column, 25 degC in
  profile 60 while the coolant is at 70 degC: a second boundary);
- ``speed_conductance``: yoke-coolant and winding-tooth conductances G (1 + k |w| / w_ref), k in 0-10;
- ``iron_in_winding``: a second iron loss in the winding node;
- ``ac_copper``: copper loss R(T_w) i^2 (1 + k_ac (|w| / w_ref)^2) (skin and proximity effects);
- ``room+...``: combinations;
- ``flux_iron``: iron losses from the flux linkage instead of the speed alone (Steinmetz): hysteresis
  P_h (|w| / w_ref) (psi / psi_ref)^2 + eddy currents P_e (|w| psi / (w_ref psi_ref))^2, with
  |psi| = |psi_pm + L_d i_d, L_q i_q| fitted once from the rotor-frame voltages (:func:`flux_model`): field
  weakening (i_d < 0) lowers the flux at high speed;
- ``voltage_iron``: P_h (|w| / w_ref) + P_e (|u_dq| / 130 V)^2 (eddy currents ~ (f B)^2 ~ u^2 from the measured
  voltage, which sits at the inverter's limit over most of both profiles);
- ``yoke_share``: the iron losses split between tooth and yoke (share fitted);
- ``winding_yoke``, ``tooth_coolant``: one more link (a star rather than a chain);
- ``coolant_g``: the yoke - coolant conductance G (1 + k (T_coolant - 20) / 50) (water-glycol viscosity);
- ``housing``: an unmeasured node (end shields) between the yoke and the room, starting at the yoke's reading.

Scores: winding RMSE of the joint fit on each profile; leave one profile out: each profile predicted from
its first readings by a fit of the other (every sensor, noise-weighted); the pooled RMSE of both.

    python benchmarks/study_paderborn_physics.py [--only NAME ...]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy import optimize

from _common import RESULTS, write
from thermo_ddp.diagnose.thermal import ThermalDiagnosisSettings
from thermo_ddp.identify.network_fit import sensor_noise
from thermo_ddp.identify.thermal_data import thermal_grid
from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file
from thermo_ddp.recordings import read_recordings

ROOT = Path(__file__).resolve().parents[1]
PROFILES = {"profile_24": (ROOT / "data" / "paderborn" / "profile_24.csv", "paderborn_profile_24.toml"),
            "profile_60": (ROOT.parent / "shared" / "data" / "paderborn" / "profile_60_first50min.csv",
                           "paderborn_profile_60.toml")}
SENSORS = ("winding", "tooth", "yoke")
GRID_S = 10.0
W_REF = 576.0  # rad/s, 5,500 rpm (profile 24's speed)
PSI_REF = 0.22  # V s/rad (mechanical), the flux linkage |psi| in profile 24 (both stages, at the voltage limit)
EXPONENTS = (1.0, 1.5, 2.0, 2.5)


def recordings() -> list:
    return [read_recordings([path], ROOT / "examples" / "columns" / cmap).recordings[0] for path, cmap in PROFILES.values()]


def flux_model() -> tuple[float, float, float]:
    """Flux linkage per mechanical radian from the rotor-frame voltages of both profiles (steady state, |w| > 100
    rad/s): psi_d = (u_q - R i_q) / w = psi_pm + L_d i_d, psi_q = -(u_d - R i_d) / w = L_q i_q (least squares)."""
    rows = [np.genfromtxt(path, delimiter=",", names=True) for path, _ in PROFILES.values()]
    d = {k: np.concatenate([r[k] for r in rows]) for k in ("u_d", "u_q", "i_d", "i_q", "motor_speed")}
    w = d["motor_speed"] * np.pi / 30
    m = np.abs(w) > 100
    r = 0.0158  # ohm per phase at 70 degC (data README)
    (psi_pm, l_d), *_ = np.linalg.lstsq(np.c_[np.ones(m.sum()), d["i_d"][m]], ((d["u_q"] - r * d["i_q"]) / w)[m], rcond=None)
    (l_q,), *_ = np.linalg.lstsq(d["i_q"][m, None], (-(d["u_d"] - r * d["i_d"]) / w)[m], rcond=None)
    return float(psi_pm), float(l_d), float(l_q)


def load(name: str, rec, flux=None) -> dict:
    """Held means over the 10 s grid, the readings at its points (and the room temperature of the CSV)."""
    path = PROFILES[name][0]
    csv = np.genfromtxt(path, delimiter=",", names=True)
    room = csv["ambient"]
    psi_pm, l_d, l_q = flux or flux_model()
    psi = np.hypot(psi_pm + l_d * csv["i_d"], l_q * csv["i_q"]) / PSI_REF  # flux linkage, per unit of profile 24's
    block = np.floor((rec.time_s - rec.time_s[0]) / GRID_S).astype(int)
    count = np.bincount(block)

    def mean(x):
        return np.bincount(block, weights=np.asarray(x, float)) / count
    w = np.abs(rec.velocity)
    first = np.flatnonzero(np.r_[True, np.diff(block) > 0])
    y = {"winding": rec.temperature_c[first], **{k: v[first] for k, v in rec.sensors.items()}}
    return {"name": name, "i2": mean(rec.current_a ** 2), "coolant": mean(rec.ambient_c), "room": mean(room),
            "w": np.array([mean((w / W_REF) ** e) for e in EXPONENTS]), "w2i2": mean(rec.current_a ** 2 * (w / W_REF) ** 2),
            "fe_h": mean(w / W_REF * psi ** 2), "fe_e": mean((w / W_REF * psi) ** 2),
            "u2": mean((np.hypot(csv["u_d"], csv["u_q"]) / 130.0) ** 2),
            "y": y, "n": len(count)}


def speed_power(u: dict, n: float) -> np.ndarray:
    """Held mean of (|w| / w_ref)^n, geometric between the lattice exponents (as identify/network.py)."""
    k = min(int((n - 1) / 0.5), 2)
    a = (n - 1 - 0.5 * k) / 0.5
    return np.exp((1 - a) * np.log(u["w"][k] + 1e-12) + a * np.log(u["w"][k + 1] + 1e-12))


class Candidate:
    """One structure: its free values (name, start, low, high, log scale) and its affine dynamics."""

    def __init__(self, name: str, motor, room=False, speed_conductance=False, iron_in_winding=False, ac=False,
                 iron="speed", yoke_share=False, links=(), coolant_g=False, housing=False):
        self.name, self.m = name, motor
        self.room, self.speed_g, self.iron_w, self.ac = room, speed_conductance, iron_in_winding, ac
        self.iron, self.yoke_share, self.links, self.coolant_g = iron, yoke_share, tuple(links), coolant_g
        self.nodes = SENSORS + (("housing",) if housing else ())
        if housing:  # an unmeasured node between the yoke and the room (end shields), starting at the yoke's reading
            self.links += (("yoke", "housing"), ("housing", "room" if room else "coolant"))
        free = [("C_winding", 2000, 2, 1e5, True), ("C_tooth", 2000, 2, 1e5, True), ("C_yoke", 2000, 2, 1e5, True),
                ("R_winding_tooth", .03, 1e-4, 100, True), ("R_tooth_yoke", .03, 1e-4, 100, True),
                ("R_yoke_coolant", .03, 1e-4, 100, True)]
        free += {"speed": [("P_iron", 200, 1e-3, 1e4, True), ("n_iron", 1.5, 1, 2.5, False)],
                 "flux": [("P_hyst", 100, 1e-3, 1e4, True), ("P_eddy", 100, 1e-3, 1e4, True)],
                 "voltage": [("P_hyst", 100, 1e-3, 1e4, True), ("P_eddy", 100, 1e-3, 1e4, True)]}[iron]
        free += [("C_housing", 5000, 2, 1e6, True)] if housing else []
        free += [("yoke_share", .3, 0, 1, False)] if yoke_share else []
        free += [(f"R_{a}_{b}", .1, 1e-4, 100, True) for a, b in self.links]
        free += [("k_coolant_g", 0.0, -0.9, 3, False)] if coolant_g else []
        free += [("R_yoke_room", .1, 1e-3, 100, True)] if room and not housing else []
        free += [("k_yoke_coolant", .5, 0, 10, False), ("k_winding_tooth", .5, 0, 10, False)] if speed_conductance else []
        free += [("P_iron_winding", 200, 1e-3, 1e4, True), ("n_iron_winding", 1.5, 1, 2.5, False)] if iron_in_winding else []
        free += [("k_ac", .1, 0, 5, False)] if ac else []
        self.names = [f[0] for f in free]
        self.log = np.array([f[4] for f in free])
        tr = lambda v, lg: np.log(v) if lg else v  # noqa: E731
        self.theta0 = np.array([tr(f[1], f[4]) for f in free])
        self.bounds = (np.array([tr(f[2], f[4]) for f in free]), np.array([tr(f[3], f[4]) for f in free]))

    def values(self, theta) -> dict:
        return {k: float(np.exp(t) if lg else t) for k, t, lg in zip(self.names, theta, self.log)}

    def dynamics(self, theta, u: dict) -> tuple[np.ndarray, np.ndarray]:
        """dT/dt = A_k T + b_k on each grid step k (nodes winding, tooth, yoke)."""
        v, m, n = self.values(theta), self.m, u["n"]
        size = len(self.nodes)
        g = np.zeros((n, size, size))
        b = np.zeros((n, size))
        speed = u["w"][0]
        links = ((0, 1, "R_winding_tooth", "k_winding_tooth"), (1, 2, "R_tooth_yoke", None))
        for i, j, r, k in links:
            c = (1 + v[k] * speed if self.speed_g and k else 1) / v[r]
            g[:, i, i] += c
            g[:, j, j] += c
            g[:, i, j] -= c
            g[:, j, i] -= c
        c = (1 + v["k_yoke_coolant"] * speed if self.speed_g else 1) / v["R_yoke_coolant"]
        c = c * (1 + v["k_coolant_g"] * (u["coolant"] - 20.0) / 50.0) if self.coolant_g else c  # viscosity
        g[:, 2, 2] += c
        b[:, 2] += c * u["coolant"]
        node = {k: i for i, k in enumerate(self.nodes)}
        for a, z in self.links:  # extra links: node - node, or node - coolant / room
            c = 1 / v[f"R_{a}_{z}"]
            g[:, node[a], node[a]] += c
            if z in node:
                g[:, node[z], node[z]] += c
                g[:, node[a], node[z]] -= c
                g[:, node[z], node[a]] -= c
            else:
                b[:, node[a]] += c * u[z]
        if self.room and "housing" not in self.nodes:
            g[:, 2, 2] += 1 / v["R_yoke_room"]
            b[:, 2] += u["room"] / v["R_yoke_room"]
        i2 = u["i2"] + (v["k_ac"] * u["w2i2"] if self.ac else 0)  # R(T) i^2 (1 + k_ac (w / w_ref)^2)
        g[:, 0, 0] -= m.resistance_ohm * m.copper_alpha_per_k * i2
        b[:, 0] += m.resistance_ohm * (1 - m.copper_alpha_per_k * m.resistance_ref_c) * i2
        iron = {"speed": lambda: v["P_iron"] * speed_power(u, v["n_iron"]),
                "flux": lambda: v["P_hyst"] * u["fe_h"] + v["P_eddy"] * u["fe_e"],
                "voltage": lambda: v["P_hyst"] * speed + v["P_eddy"] * u["u2"]}[self.iron]()
        share = v["yoke_share"] if self.yoke_share else 0.0
        b[:, 1] += (1 - share) * iron
        b[:, 2] += share * iron
        if self.iron_w:
            b[:, 0] += v["P_iron_winding"] * speed_power(u, v["n_iron_winding"])
        cap = np.array([v[f"C_{k}"] for k in self.nodes])
        return -g / cap[None, :, None], b / cap[None, :]

    def simulate(self, theta, u: dict) -> np.ndarray:
        a, b = self.dynamics(theta, u)
        x = np.array([u["y"][s][0] for s in SENSORS] + [u["y"]["yoke"][0]] * (len(self.nodes) - 3))
        step = np.linalg.inv(np.eye(len(self.nodes))[None] - 0.5 * GRID_S * a)
        out = np.zeros((u["n"], len(self.nodes)))
        out[0] = x
        for k in range(u["n"] - 1):
            x = x + GRID_S * step[k] @ (a[k] @ x + b[k])
            out[k + 1] = x
        return out


def residuals(cand: Candidate, theta, data: list[dict], noise: dict) -> np.ndarray:
    r = np.concatenate([(cand.simulate(theta, u)[:, i] - u["y"][s]) / noise[s] for u in data
                        for i, s in enumerate(SENSORS)])
    return r if np.all(np.isfinite(r)) else np.full_like(r, 1e6)


def fit(cand: Candidate, data: list[dict], noise: dict, theta0=None) -> np.ndarray:
    lo, hi = cand.bounds
    start = np.clip(cand.theta0 if theta0 is None else theta0, lo, hi)
    return optimize.least_squares(lambda t: residuals(cand, t, data, noise), start, bounds=(lo, hi), max_nfev=300,
                                  x_scale="jac", diff_step=1e-5).x


def winding_rmse(cand: Candidate, theta, u: dict) -> float:
    return float(np.sqrt(np.mean((cand.simulate(theta, u)[:, 0] - u["y"]["winding"]) ** 2)))


def study(cand: Candidate, data: list[dict], noise: dict) -> dict:
    start = time.perf_counter()
    joint = fit(cand, data, noise)
    held = {}
    for k, u in enumerate(data):
        others = [d for j, d in enumerate(data) if j != k]
        held[u["name"]] = winding_rmse(cand, fit(cand, others, noise, joint), u)
    sizes = np.array([u["n"] for u in data])
    pooled = float(np.sqrt(np.sum(sizes * np.array(list(held.values())) ** 2) / sizes.sum()))
    out = {"joint_winding_rmse_c": {u["name"]: winding_rmse(cand, joint, u) for u in data},
           "held_out_winding_rmse_c": held, "held_out_pooled_c": pooled, "values": cand.values(joint),
           "seconds": time.perf_counter() - start}
    print(f"{cand.name:28s} joint " + " / ".join(f"{v:.2f}" for v in out["joint_winding_rmse_c"].values())
          + " K | held out " + " / ".join(f"{v:.2f}" for v in held.values()) + f" K, pooled {pooled:.2f} K", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args()
    motor = load_parameters(packaged_parameter_file("paderborn_pmsm")).motor
    flux = flux_model()
    data = [load(name, rec, flux) for name, rec in zip(PROFILES, recordings())]
    params = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    grids = [thermal_grid(r, params, ThermalDiagnosisSettings().fit) for r in recordings()]
    noise = {s: sensor_noise(grids, s) for s in SENSORS}  # the diagnosis' own weights
    cands = [Candidate("chain", motor), Candidate("room", motor, room=True),
             Candidate("room+speed_conductance", motor, room=True, speed_conductance=True),
             Candidate("room+iron_in_winding", motor, room=True, iron_in_winding=True),
             Candidate("ac_copper", motor, ac=True), Candidate("room+ac_copper", motor, room=True, ac=True)]
    cands += [Candidate("room+ac_copper+flux_iron", motor, room=True, ac=True, iron="flux"),
              Candidate("room+flux_iron", motor, room=True, iron="flux"),
              Candidate("room+ac_copper+voltage_iron", motor, room=True, ac=True, iron="voltage"),
              Candidate("room+voltage_iron", motor, room=True, iron="voltage"),
              Candidate("room+ac_copper+yoke_share", motor, room=True, ac=True, yoke_share=True),
              Candidate("room+ac_copper+winding_yoke", motor, room=True, ac=True, links=[("winding", "yoke")]),
              Candidate("room+ac_copper+tooth_coolant", motor, room=True, ac=True, links=[("tooth", "coolant")]),
              Candidate("room+ac_copper+coolant_g", motor, room=True, ac=True, coolant_g=True),
              Candidate("room+ac_copper+housing", motor, room=True, ac=True, housing=True),
              Candidate("room+ac_copper+flux_iron+housing", motor, room=True, ac=True, iron="flux", housing=True)]
    cands = [c for c in cands if args.only is None or c.name in args.only]
    results = {c.name: study(c, data, noise) for c in cands}
    previous = RESULTS / "paderborn_physics.json"  # --only keeps the other candidates' results
    kept = json.loads(previous.read_text())["candidates"] if args.only and previous.exists() else {}
    write("paderborn_physics", {"grid_s": GRID_S, "noise_c": noise, "flux_model": dict(zip(("psi_pm", "l_d", "l_q"), flux)),
                                "candidates": {**kept, **results}})


if __name__ == "__main__":
    main()
