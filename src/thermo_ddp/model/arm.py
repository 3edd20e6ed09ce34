"""The Talos left arm from example-robot-data, reduced to chosen joints, with a payload.

We use the PyPI package ``example-robot-data`` 6 (URDFs only) and build the Pinocchio model
ourselves; its armature (N^2 B_m) is set here from the motor parameter files, once.
"""
from __future__ import annotations

import functools
import logging
import os
import site
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np
import pinocchio as pin

from ..errors import InputError
from .parameters import Bound

log = logging.getLogger(__name__)

ROBOT_URDF = "talos_data/robots/talos_reduced.urdf"
LEFT_ARM = tuple(f"arm_left_{i}_joint" for i in range(1, 8))
ELBOW = "arm_left_4_joint"
WRIST = "arm_left_7_joint"  # joints 5-7 share one origin, the wrist centre
GRIPPER_FRAME = "gripper_left_base_link"
GRIPPER_LEVER_M = 0.357  # elbow axis to gripper_left_base_link in talos_reduced.urdf: 0.3573 m
# Payload at the gripper: Talos itself weighs about 100 kg (PAL Robotics datasheet: 95 kg); no arm lifts more.
PAYLOAD_KG = Bound(0.0, 100.0, "kg", "Talos itself weighs about 100 kg; no arm of it lifts more")
PAYLOAD_LEVER_M = Bound(0.0, 0.6, "m", "from the elbow axis along the forearm, the gripper at 0.357 m")


def robots_dir() -> Path:
    """example-robot-data's ``robots/`` folder (env EXAMPLE_ROBOT_DATA_MODEL_DIR wins)."""
    candidates = [os.environ.get("EXAMPLE_ROBOT_DATA_MODEL_DIR", "")]
    roots = [*site.getsitepackages(), site.getusersitepackages(), *sys.path]
    candidates += [str(Path(r) / "cmeel.prefix/share/example-robot-data/robots") for r in roots]
    for c in candidates:
        if c and (Path(c) / ROBOT_URDF).is_file():
            return Path(c)
    raise FileNotFoundError("example-robot-data URDFs not found: pip install 'example-robot-data>=6'")


@dataclass(frozen=True)
class ArmSettings:
    """Which joints move, where the others are held, and the payload.

    ``posture`` gives the angle of any locked joint (default 0 rad: with every arm joint at 0 the
    upper arm hangs vertically and the elbow lifts the forearm against gravity).
    """

    joints: tuple[str, ...] = (ELBOW,)
    posture: Mapping[str, float] = field(default_factory=dict)
    payload_kg: float = 0.0
    payload_lever_m: float = GRIPPER_LEVER_M
    robot: str = ROBOT_URDF

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(self.joints))
        if not self.joints or len(set(self.joints)) != len(self.joints):
            raise InputError("arm", "joints", list(self.joints), "need distinct joint names")
        for j in self.joints:
            if j not in LEFT_ARM:
                raise InputError("arm", "joints", j, f"not a left-arm joint; choose from {', '.join(LEFT_ARM)}")
        object.__setattr__(self, "payload_kg", PAYLOAD_KG.check("arm", "payload_kg", self.payload_kg, "out of range"))
        object.__setattr__(self, "payload_lever_m",
                           PAYLOAD_LEVER_M.check("arm", "payload_lever_m", self.payload_lever_m, "out of range"))


@dataclass(frozen=True)
class Arm:
    """A reduced Pinocchio model of the arm with its payload; joints ordered as ``joints``."""

    settings: ArmSettings
    model: pin.Model
    locked_joints: Mapping[str, float]
    payload_frame: str
    payload_translation_m: np.ndarray
    # Spatial inertias (6x6, one per moving joint) of the reduced model without the payload, and of 1 kg of
    # payload: the model's inertias are ``unloaded + payload_kg * per_payload_kg``, so the payload can be a
    # runtime parameter of the CasADi dynamics (thermo_ddp.model.rigid_body) while this model keeps its own.
    unloaded_inertias: tuple[np.ndarray, ...] = field(repr=False, default=())
    inertias_per_payload_kg: tuple[np.ndarray, ...] = field(repr=False, default=())

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(self.model.names[1:])

    @property
    def nv(self) -> int:
        return self.model.nv

    def joint_index(self, name: str) -> int:
        return self.joints.index(name)

    def payload_dict(self) -> dict:
        return {"mass_kg": self.settings.payload_kg, "lever_m": self.settings.payload_lever_m,
                "frame": self.payload_frame, "translation_m": self.payload_translation_m.tolist()}

    def gravity_torque_nm(self, q: np.ndarray) -> np.ndarray:
        """Gravity torques at posture ``q`` (nv,), or at each row of ``q`` (K, nv)."""
        q = np.asarray(q, float)
        data = self.model.createData()
        if q.ndim == 1:
            return pin.computeGeneralizedGravity(self.model, data, q)
        return np.array([pin.computeGeneralizedGravity(self.model, data, row) for row in q])


def _payload_placement(full: pin.Model, lever_m: float) -> tuple[str, np.ndarray]:
    """Body (joint) carrying the payload and the payload's position in its frame.

    The payload sits ``lever_m`` from the elbow axis on the line to the gripper (neutral posture).
    Beyond the wrist centre it is held by the hand, so it moves with the wrist joints when they are
    planned; otherwise it hangs on the forearm. Locked joints make both the same rigid body.
    """
    data = full.createData()
    pin.framesForwardKinematics(full, data, pin.neutral(full))
    elbow, wrist = data.oMi[full.getJointId(ELBOW)], data.oMi[full.getJointId(WRIST)]
    to_gripper = elbow.actInv(data.oMf[full.getFrameId(GRIPPER_FRAME)]).translation
    point = lever_m * to_gripper / np.linalg.norm(to_gripper)
    if lever_m > np.linalg.norm(elbow.actInv(wrist).translation):
        return WRIST, wrist.actInv(elbow.act(point))
    return ELBOW, point


@functools.lru_cache(maxsize=4)
def _robot_model(urdf_path: str) -> pin.Model:
    """The parsed URDF (read only: :func:`build_arm` copies it before changing anything)."""
    return pin.buildModelFromUrdf(urdf_path)


def build_arm(settings: ArmSettings = ArmSettings(), armature_kg_m2: Mapping[str, float] | None = None) -> Arm:
    """Load Talos, lock every joint but ``settings.joints``, add the payload and the armature."""
    full = _robot_model(str(robots_dir() / settings.robot))
    names = list(full.names[1:])
    for j in settings.posture:
        if j not in names:
            raise InputError("arm", "posture", j, "unknown joint")
    q_lock = pin.neutral(full)
    for j, angle in settings.posture.items():
        q_lock[full.joints[full.getJointId(j)].idx_q] = angle
    lock_ids = [full.getJointId(n) for n in names if n not in settings.joints]
    carrier, translation = _payload_placement(full, settings.payload_lever_m)

    def reduced(payload_kg: float) -> pin.Model:
        loaded = full.copy()
        if payload_kg > 0:
            loaded.appendBodyToJoint(loaded.getJointId(carrier), pin.Inertia(payload_kg, translation, np.zeros((3, 3))),
                                     pin.SE3.Identity())
        return pin.buildReducedModel(loaded, lock_ids, q_lock)

    model, unloaded, one_kg = reduced(settings.payload_kg), reduced(0.0), reduced(1.0)
    order = [list(model.names).index(j) for j in settings.joints]
    if order != sorted(order):
        raise InputError("arm", "joints", list(settings.joints), "list joints from shoulder to wrist")
    for j, value in (armature_kg_m2 or {}).items():
        model.armature[model.getJointId(j) - 1] = value
    locked = {full.names[i]: float(q_lock[full.joints[i].idx_q]) for i in lock_ids}
    base = tuple(unloaded.inertias[i].matrix() for i in range(1, model.njoints))
    per_kg = tuple(one_kg.inertias[i].matrix() - b for i, b in zip(range(1, model.njoints), base))
    log.debug("arm %s, payload %.1f kg at %s", settings.joints, settings.payload_kg, translation)
    return Arm(settings, model, locked, carrier.replace("_joint", "_link"), translation, base, per_kg)
