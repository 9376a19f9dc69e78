"""The paper's evaluation protocol (Section IV) as simulation settings.

Path (1.5, 1.2) -> (8.5, 1.2) -> (8.5, 5.8) -> (1.5, 5.8) -> (1.5, 3.5) -> (5, 3.5) in
the paper office, 0.5 m/s, 5 frames/s, bearing noise 2 deg, odometry noise 2 cm and
1 deg per frame, scores 1.0. Scenarios: ``nominal`` (Table I); ``occlusion``
(Table II: from t = 10 s and t = 35 s the person faces the nearest corner for 10 s
with the front 180 deg of the view blocked); ``missing`` (Table III: each frame loses
a random share of its detections, up to all of them).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal

from app.simulation.simulator import CornerVisit, SimulationConfig

Scenario = Literal["nominal", "occlusion", "missing"]

PAPER_PATH: tuple[tuple[float, float], ...] = (
    (1.5, 1.2),
    (8.5, 1.2),
    (8.5, 5.8),
    (1.5, 5.8),
    (1.5, 3.5),
    (5.0, 3.5),
)


def paper_config(scenario: Scenario = "nominal", fov_deg: float = 360.0) -> SimulationConfig:
    """The simulation settings of one cell of the paper's Tables I-III."""
    base = SimulationConfig(
        path=PAPER_PATH,
        speed_mps=0.5,
        rate_hz=5.0,
        fov_deg=fov_deg,
        bearing_noise_deg=2.0,
        odometry_noise_m=0.02,
        odometry_noise_deg=1.0,
    )
    if scenario == "occlusion":
        return replace(
            base,
            corner_visits=(CornerVisit(10.0, 10.0), CornerVisit(35.0, 10.0)),
            blocked_sector_deg=180.0,
        )
    if scenario == "missing":
        return replace(base, random_loss=True)
    if scenario != "nominal":
        raise ValueError(f"unknown scenario {scenario!r}: use nominal, occlusion or missing")
    return base
