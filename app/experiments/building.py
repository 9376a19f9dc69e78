"""`bearings experiments --suite building`: a walk through the bundled two-wing floor.

The floor (``two_wing_office``, 38 m x 24 m, imported from an occupancy grid) has two
corridors with the same rooms and doorways; only furniture and fittings differ. The
walk starts in the west corridor with no initial pose (global localization), enters a
meeting room and an office in the west wing, crosses the lobby, and visits an office
and the print room in the east wing (about 84 m, 3 minutes at 0.5 m/s, 5 frames/s).

Conditions: a 360 deg camera; a 180 deg camera; one false detection per frame
(Poisson) with the 360 deg camera; and a kidnap between the wings (at ``KIDNAP_AT_S``
the person, walking the east corridor, is carried to the west corridor without
odometry and walks on east from there).

Figures per condition, the integrity suite's (:mod:`app.experiments.integrity`): time
to first fix (first converged frame, and first converged frame within 1 m), tail error,
confidently-wrong frames, availability, flips per minute, protection coverage; for the
kidnap, the time from the kidnap to the next right fix.
"""

from __future__ import annotations

import json
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from app.bench import machine_line
from app.experiments import integrity as m
from app.experiments.hard_maps import (
    BUILDING_KIDNAP_AT_S,
    BUILDING_KIDNAP_POSE,
    BUILDING_MAP_NAME,
    BUILDING_WALK,
)
from app.experiments.runner import map_jobs
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.maps.check import load_map
from app.maps.model import SemanticMap
from app.resources import bundled_maps_dir
from app.simulation.simulator import SimulationConfig, simulate

# The walk through the bundled floor is defined with the other suites' maps.
MAP_NAME = BUILDING_MAP_NAME
WALK = BUILDING_WALK
KIDNAP_AT_S = BUILDING_KIDNAP_AT_S
KIDNAP_POSE = BUILDING_KIDNAP_POSE

#: Condition name -> (field of view, simulation changes).
CONDITIONS: dict[str, tuple[float, dict[str, object]]] = {
    "nominal-360": (360.0, {}),
    "nominal-180": (180.0, {}),
    "clutter-360": (360.0, {"false_rate": 1.0}),
    "kidnap-360": (360.0, {"kidnap_at_s": KIDNAP_AT_S, "kidnap_pose": KIDNAP_POSE}),
}


def floor() -> SemanticMap:
    return load_map(bundled_maps_dir() / f"{MAP_NAME}.json")


def simulation(condition: str) -> SimulationConfig:
    fov, changes = CONDITIONS[condition]
    sim = SimulationConfig(
        path=WALK,
        fov_deg=fov,
        bearing_noise_deg=2.0,
        odometry_noise_m=0.02,
        odometry_noise_deg=1.0,
    )
    return replace(sim, **changes)  # type: ignore[arg-type]


@dataclass(frozen=True)
class BuildingRun:
    """One seed of one condition: per-frame arrays, each shape (T,)."""

    condition: str
    seed: int
    t: np.ndarray
    truth_xy: np.ndarray
    est_xy: np.ndarray
    err_m: np.ndarray
    converged: np.ndarray
    protection_m: np.ndarray  # nan where None
    step_ms: np.ndarray
    particles: np.ndarray


def run_condition(condition: str, seed: int, particles: int) -> BuildingRun:
    """Simulate the walk under one condition and run the filter from a global start."""
    semantic_map = floor()
    world_rng, filter_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence([seed, 13]).spawn(2)
    )
    frames = simulate(semantic_map, simulation(condition), world_rng)
    config = FilterConfig(particles=particles, fov_deg=CONDITIONS[condition][0])
    pf = ParticleFilter(semantic_map, config, rng=filter_rng)
    n = len(frames)
    est = np.empty((n, 2))
    truth = np.empty((n, 2))
    conv = np.zeros(n, dtype=bool)
    prot = np.full(n, np.nan)
    ms = np.empty(n)
    count = np.empty(n, dtype=np.int64)
    for i, f in enumerate(frames):
        t0 = time.perf_counter()
        e = pf.step(f.odometry, f.detections)
        ms[i] = (time.perf_counter() - t0) * 1e3
        est[i] = e.x, e.y
        truth[i] = f.truth.x, f.truth.y
        conv[i] = e.converged
        radius = getattr(e, "protection_m", None)
        if radius is not None:
            prot[i] = radius
        count[i] = e.n_particles
    t = np.array([f.t for f in frames])
    err = np.hypot(*(est - truth).T)
    return BuildingRun(condition, seed, t, truth, est, err, conv, prot, ms, count)


def first_right_fix_s(run: BuildingRun, since_s: float = 0.0) -> float:
    """Seconds from ``since_s`` to the first converged frame within ``WRONG_M`` (inf: never)."""
    hit = np.flatnonzero(run.converged & (run.t >= since_s) & (run.err_m <= m.WRONG_M))
    return float(run.t[hit[0]] - since_s) if hit.size else float("inf")


def _job(args: tuple[str, int, int]) -> BuildingRun:
    return run_condition(*args)


def run_suite(
    conditions: list[str],
    seeds: int,
    particles: int,
    workers: int,
    progress: Callable[[], object] | None = None,
) -> list[BuildingRun]:
    jobs = [(c, seed, particles) for c in conditions for seed in range(seeds)]
    return map_jobs(_job, jobs, workers, progress)


def summarize(runs: list[BuildingRun]) -> list[dict[str, object]]:
    by: dict[str, list[BuildingRun]] = defaultdict(list)
    for r in runs:
        by[r.condition].append(r)
    rows = []
    for condition, rs in by.items():
        row: dict[str, object] = {"condition": condition}
        row.update(m.metrics(rs))  # type: ignore[arg-type]  # same per-frame fields
        right = [first_right_fix_s(r) for r in rs]
        row["median_first_right_fix_s"] = float(np.median(right))
        row["first_fix_s_per_seed"] = [round(m.first_fix_s(r), 1) for r in rs]  # type: ignore[arg-type]
        # Wrong frames before the first right fix: confidently wrong while still searching.
        row["wrong_before_first_fix"] = int(
            sum(
                np.sum(r.converged & (r.err_m > m.WRONG_M) & (r.t < r.t[0] + rt))
                for r, rt in zip(rs, right, strict=True)
            )
        )
        if condition.startswith("kidnap"):
            rec = [first_right_fix_s(r, since_s=KIDNAP_AT_S) for r in rs]
            row["median_recovery_s"] = float(np.median(rec))
        row["max_particles"] = int(max(int(r.particles.max()) for r in rs))
        rows.append(row)
    return rows


def _f(v: object, fmt: str) -> str:
    if isinstance(v, float) and not np.isfinite(v):
        return "-" if np.isnan(v) else "never"
    return format(v, fmt)


def markdown_table(rows: list[dict[str, object]]) -> str:
    lines = [
        "| condition | first fix (s) | first fix within 1 m (s) | recovery after kidnap (s) "
        "| tail error p95 (m) | confidently wrong | availability | flips / min "
        "| protection coverage | step median (ms) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['condition']} | {_f(r['median_first_fix_s'], '.1f')} "
            f"| {_f(r['median_first_right_fix_s'], '.1f')} "
            f"| {_f(r.get('median_recovery_s', float('nan')), '.1f')} "
            f"| {_f(r['tail_err_m'], '.2f')} "
            f"| {r['wrong_frames']} / {r['frames']} ({_f(100 * r['wrong_share'], '.2f')} %) "  # type: ignore[operator]
            f"| {_f(r['availability'], '.2f')} | {_f(r['flips_per_min'], '.2f')} "
            f"| {_f(r['coverage'], '.3f')} | {_f(r['median_step_ms'], '.2f')} |"
        )
    return "\n".join(lines)


def markdown(rows: list[dict[str, object]], *, seconds: float, particles: int, seeds: int) -> str:
    return "\n".join(
        [
            "# Building suite: the two-wing floor",
            "",
            f"Generated by `bearings experiments --suite building` in {seconds:.0f} s: "
            f"{seeds} seeds per condition, up to {particles} particles (adaptive), global "
            "start in the west corridor, 5 frames/s, 0.5 m/s, bearing noise 2 deg, odometry "
            "noise 2 cm and 1 deg per frame, camera range 15 m. Walk and conditions: "
            "`app/experiments/building.py`; metrics: `app/experiments/integrity.py`.",
            "",
            machine_line(),
            "",
            "* first fix: median over seeds of the time of the first converged frame; "
            "'within 1 m': the first converged frame that is also right",
            f"* recovery after kidnap: from the kidnap at {KIDNAP_AT_S:g} s to the next "
            "converged frame within 1 m",
            f"* confidently wrong: converged and more than {m.WRONG_M:g} m off (frames, share)",
            f"* availability: share of frames converged among those within {m.RIGHT_M:g} m",
            f"* flips: converged -> not converged while within {m.FLIP_M:g} m, per minute",
            "* tail error: 95th percentile of the error over converged frames",
            "* protection coverage: share of converged frames with the error within "
            "`protection_m` ('-' when the filter reports none)",
            "",
            markdown_table(rows),
            "",
            "First fix per seed (s): "
            + "; ".join(f"{r['condition']}: {r['first_fix_s_per_seed']}" for r in rows),
            "",
        ]
    )


def figure(runs: list[BuildingRun], out: Path) -> Path:
    """The floor with one walk per condition (truth and estimate), and errors over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    semantic_map = floor()
    conditions = list(dict.fromkeys(r.condition for r in runs))
    fig, axes = plt.subplots(2, 1, figsize=(12, 11), height_ratios=(3, 2))
    ax = axes[0]
    for x1, y1, x2, y2 in semantic_map.walls:
        ax.plot([x1, x2], [y1, y2], color="black", lw=1.2)
    ax.scatter(*semantic_map.object_xy.T, s=6, color="grey")
    first = {c: next(r for r in runs if r.condition == c) for c in conditions}
    colours = dict(
        zip(conditions, ("tab:green", "tab:blue", "tab:orange", "tab:red"), strict=False)
    )
    ref = first[conditions[0]]
    ax.plot(*ref.truth_xy.T, color="black", lw=2, ls="--", label="truth")
    for c, r in first.items():
        sel = r.converged
        ax.scatter(*r.est_xy[sel].T, s=3, color=colours[c], label=f"estimate, {c} (converged)")
    ax.set_aspect("equal")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.06), ncol=3)
    ax.set_title(f"{MAP_NAME}: seed {ref.seed} of each condition")
    ax = axes[1]
    for c, r in first.items():
        ax.plot(r.t, r.err_m, color=colours[c], lw=1, label=c)
    ax.axvline(KIDNAP_AT_S, color="tab:red", ls=":", lw=1)
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position error (m)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "building.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def run(
    out: Path, *, seeds: int, particles: int, workers: int, quick: bool
) -> list[dict[str, object]]:
    """Run the suite, write building.md/.json and the figure; return the rows."""
    from tqdm import tqdm

    conditions = list(CONDITIONS)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    with tqdm(total=len(conditions) * seeds, desc="building runs", unit="run") as bar:
        runs = run_suite(conditions, seeds, particles, workers, bar.update)
    seconds = time.perf_counter() - started
    rows = summarize(runs)
    (out / "building.json").write_text(json.dumps(rows, indent=1), encoding="utf-8")
    (out / "building.md").write_text(
        markdown(rows, seconds=seconds, particles=particles, seeds=seeds), encoding="utf-8"
    )
    figure(runs, out)
    return rows
