"""Walks for demos: a closed loop on any map, and the settings a demo visitor can pick."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from app.maps.geometry import segments_cross_walls
from app.maps.model import SemanticMap
from app.maps.prepare import ensure_prepared
from app.simulation.scenarios import PAPER_PATH, paper_config
from app.simulation.simulator import CornerVisit, SimulationConfig


def loop_path(
    semantic_map: SemanticMap, rng: np.random.Generator, points: int = 6
) -> tuple[tuple[float, float], ...]:
    """A closed walk through the free space: the paper's path on the paper office,
    elsewhere ``points`` random free points, each in line of sight of the previous."""
    if semantic_map.name == "paper_office":
        return (*PAPER_PATH, PAPER_PATH[0])
    fs = ensure_prepared(semantic_map).free_space
    path = [tuple(fs.sample(1, rng)[0])]
    tries = 0
    while len(path) < points and tries < 2000:
        tries += 1
        cand = fs.sample(1, rng)[0]
        last = np.array(path[-1])
        if np.hypot(*(cand - last)) < 1.5:
            continue
        if (
            semantic_map.walls.shape[0]
            and segments_cross_walls(last[None], cand[None], semantic_map.walls)[0]
        ):
            continue
        path.append(tuple(cand))
    path.append(path[0])
    return tuple((round(float(x), 3), round(float(y), 3)) for x, y in path)


def demo_config(
    semantic_map: SemanticMap,
    rng: np.random.Generator,
    *,
    fov_deg: float = 360.0,
    occlusion: bool = False,
    missing: bool = False,
    false_rate: float = 0.0,
    bearing_noise_deg: float = 2.0,
) -> SimulationConfig:
    """A looping demo walk with the faults a visitor switched on."""
    cfg = replace(
        paper_config("nominal", fov_deg),
        path=loop_path(semantic_map, rng),
        random_loss=missing,
        false_rate=false_rate,
        bearing_noise_deg=bearing_noise_deg,
    )
    if occlusion:
        cfg = replace(cfg, corner_visits=(CornerVisit(10.0, 10.0),), blocked_sector_deg=180.0)
    return cfg
