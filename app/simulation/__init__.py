"""A person walking a map with a virtual spherical camera: frames with ground truth."""

from app.simulation.camera import CameraModel, visible_objects
from app.simulation.phone import PhoneEffects, PhoneFrame, simulate_phone
from app.simulation.scenarios import PAPER_PATH, Scenario, paper_config
from app.simulation.simulator import SimFrame, SimulationConfig, simulate

__all__ = [
    "PAPER_PATH",
    "CameraModel",
    "PhoneEffects",
    "PhoneFrame",
    "Scenario",
    "SimFrame",
    "SimulationConfig",
    "paper_config",
    "simulate",
    "simulate_phone",
    "visible_objects",
]
