"""Simulated elbow ("testbed"): a true plant with the physics the baseline model lacks.

Independent of the package's model code (numpy equations, scipy integration), it generates
recordings of the seed report's experiments for the identification and diagnosis tests.
"""
from .experiments import (COLUMNS, EXPERIMENTS, JOINT, LOGGED_COLUMNS, SimulatedRecording, Truth, biceps, programmed,
                          random_campaign, random_recording, static_3a, static_4a, static_hold, winding_pulses)
from .physics import (EFFECTS, Ambient, PlantParameters, PlantSolution, Profile, motor_voltage_v, simulate,
                      steady_state)
from .sensors import SensorSettings

__all__ = ["COLUMNS", "EFFECTS", "EXPERIMENTS", "JOINT", "LOGGED_COLUMNS", "Ambient", "PlantParameters", "PlantSolution", "Profile",
           "SensorSettings", "SimulatedRecording", "Truth", "biceps", "programmed", "random_campaign", "random_recording",
           "motor_voltage_v", "simulate", "static_3a", "static_4a", "static_hold", "steady_state", "winding_pulses"]
