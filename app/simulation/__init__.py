"""A person walking a map with a virtual spherical camera: frames with ground truth."""

from app.simulation.camera import CameraModel, visible_objects
from app.simulation.scenarios import PAPER_PATH, Scenario, paper_config
from app.simulation.simulator import SimFrame, SimulationConfig, simulate

__all__ = [
    "PAPER_PATH",
    "CameraModel",
    "Scenario",
    "SimFrame",
    "SimulationConfig",
    "paper_config",
    "simulate",
    "visible_objects",
]
