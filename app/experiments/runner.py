"""Run table cells over seeds, in parallel processes, and collect per-frame errors."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from app.experiments.protocol import Cell
from app.localization.filter import ParticleFilter
from app.maps.check import load_map
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap
from app.resources import bundled_maps_dir
from app.simulation.simulator import simulate


@dataclass(frozen=True)
class Run:
    """One seed of one cell: per-frame arrays, each shape (T,)."""

    cell: Cell
    seed: int
    t: np.ndarray
    truth_xy: np.ndarray  # (T, 2)
    est_xy: np.ndarray  # (T, 2)
    pos_err_m: np.ndarray
    head_err_deg: np.ndarray
    converged: np.ndarray
    particles: np.ndarray


_MAP_CACHE: dict[str, SemanticMap] = {}


def paper_office() -> SemanticMap:
    if "paper_office" not in _MAP_CACHE:
        _MAP_CACHE["paper_office"] = load_map(bundled_maps_dir() / "paper_office.json")
    return _MAP_CACHE["paper_office"]


def run_cell(cell: Cell, seed: int, particles: int) -> Run:
    """Simulate the cell's walk with ``seed`` and run the filter over it (global start)."""
    semantic_map = paper_office()
    # Distinct streams for the world and the filter, both fixed by the seed.
    world_rng, filter_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2)
    )
    frames = simulate(semantic_map, cell.simulation(), world_rng)
    pf = ParticleFilter(semantic_map, cell.filter_config(particles), rng=filter_rng)
    n = len(frames)
    est = np.empty((n, 2))
    truth = np.empty((n, 2))
    head = np.empty(n)
    conv = np.empty(n, dtype=bool)
    count = np.empty(n, dtype=np.int64)
    for i, f in enumerate(frames):
        e = pf.step(f.odometry, f.detections)
        est[i] = e.x, e.y
        truth[i] = f.truth.x, f.truth.y
        head[i] = abs(float(np.degrees(wrap_angle(e.theta_rad - f.truth.theta_rad))))
        conv[i] = e.converged
        count[i] = e.n_particles
    t = np.array([f.t for f in frames])
    err = np.hypot(*(est - truth).T)
    return Run(cell, seed, t, truth, est, err, head, conv, count)


J = TypeVar("J")
R = TypeVar("R")


def _job(args: tuple[Cell, int, int]) -> Run:
    return run_cell(*args)


def map_jobs(
    job: Callable[[J], R],
    jobs: Sequence[J],
    workers: int,
    progress: Callable[[], object] | None = None,
) -> list[R]:
    """``job`` over ``jobs`` in ``workers`` processes (in this one when 1), results in the
    jobs' order; ``progress`` is called after each. ``job`` must be a module-level
    function (the processes import it)."""
    results: list[R] = []
    if workers <= 1:
        for args in jobs:
            results.append(job(args))
            if progress:
                progress()
        return results
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for run in pool.map(job, jobs, chunksize=1):
            results.append(run)
            if progress:
                progress()
    return results


def run_all(
    jobs: list[tuple[Cell, int, int]],
    workers: int,
    progress: Callable[[], object] | None = None,
) -> list[Run]:
    """Run every (cell, seed, particles) job; results in the jobs' order."""
    return map_jobs(_job, jobs, workers, progress)
