"""Least-squares identification (mechanical here; thermal alongside) and shared fit reports."""
from .fit_report import FitResult, failed_fit, linear_fit, result_from_jacobian
from .mechanical import (BASELINE_TERMS, MECHANICAL_TERMS, REFERENCE_TERMS, JointKinematics, MechanicalSettings,
                         fit_kinematics, identify_mechanical, identify_mechanical_files, identify_torque_current,
                         joint_kinematics, predict_effort)

__all__ = ["FitResult", "failed_fit", "linear_fit", "result_from_jacobian", "BASELINE_TERMS", "MECHANICAL_TERMS",
           "REFERENCE_TERMS", "JointKinematics", "MechanicalSettings", "fit_kinematics", "identify_mechanical",
           "identify_mechanical_files", "identify_torque_current", "joint_kinematics", "predict_effort"]
