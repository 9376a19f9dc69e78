"""Figures like the paper's: trajectories (Figs. 5, 7, 9) and errors over time (6, 8, 10).

The error figures also draw the posterior Cramér-Rao bound of the filtering problem
along the true path (:mod:`app.experiments.pcrb`, same bearing and odometry noise as
the simulator): no estimator using the detections and odometry so far can do better
on average. :func:`single_frame_crlb_m` (one frame alone, no odometry) is kept for
comparison.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from app.experiments.pcrb import pcrb_position_m
from app.experiments.runner import Run
from app.localization.types import Pose
from app.maps.model import SemanticMap
from app.simulation.camera import CameraModel, visible_objects
from app.simulation.simulator import simulate

COLOURS = {180.0: "tab:blue", 270.0: "tab:red", 360.0: "tab:green"}
FIGURE_NUMBERS = {"I": (5, 6), "II": (7, 8), "III": (9, 10)}


def single_frame_crlb_m(
    semantic_map: SemanticMap, pose: Pose, fov_deg: float, sigma_deg: float
) -> float:
    """Lower bound (m) on one frame's position error from bearings to visible objects."""
    idx, _ = visible_objects(semantic_map, pose, CameraModel(fov_deg))
    if idx.size < 3:
        return float("nan")
    d = semantic_map.object_xy[idx] - np.array([pose.x, pose.y])
    r2 = np.sum(d * d, axis=1)
    jac = np.column_stack([d[:, 1] / r2, -d[:, 0] / r2, -np.ones(idx.size)])
    fisher = jac.T @ jac / np.radians(sigma_deg) ** 2
    try:
        cov = np.linalg.inv(fisher)
    except np.linalg.LinAlgError:
        return float("nan")
    return float(np.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))


def _pcrb_of(run: Run, semantic_map: SemanticMap) -> np.ndarray:
    """The PCRB along the run's true path, with the simulator's noise levels."""
    sim = run.cell.simulation()
    frames = simulate(semantic_map, sim, np.random.default_rng(0))
    return pcrb_position_m(
        semantic_map,
        [f.truth for f in frames],
        run.cell.fov_deg,
        sim.bearing_noise_deg,
        sim.odometry_noise_m,
        sim.odometry_noise_deg,
        sim.max_range_m,
    )


def _draw_map(ax: plt.Axes, semantic_map: SemanticMap) -> None:
    for x1, y1, x2, y2 in semantic_map.walls:
        ax.plot([x1, x2], [y1, y2], color="black", lw=2)
    markers = {"door": "s", "window": "^", "table": "o"}
    for cls, members in semantic_map.class_members.items():
        xy = semantic_map.object_xy[members]
        ax.scatter(xy[:, 0], xy[:, 1], marker=markers.get(cls, "x"), color="grey", s=40, label=cls)


def figures(runs: list[Run], semantic_map: SemanticMap, out: Path) -> list[Path]:
    """Write the trajectory and error figures for Tables I-III; return the paths."""
    written: list[Path] = []
    for table, (traj_no, err_no) in FIGURE_NUMBERS.items():
        sel = [r for r in runs if r.cell.table == table]
        if not sel:
            continue
        first_seed = min(r.seed for r in sel)
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
        for ax, cfg in zip(axes, ("paper", "bearings"), strict=True):
            _draw_map(ax, semantic_map)
            shown = False
            for r in sel:
                if r.seed != first_seed or r.cell.config != cfg:
                    continue
                if not shown:
                    ax.plot(*r.truth_xy.T, "k--", lw=1.5, label="ground truth")
                    shown = True
                ax.plot(
                    *r.est_xy.T,
                    color=COLOURS[r.cell.fov_deg],
                    lw=1,
                    label=f"{r.cell.fov_deg:.0f} deg",
                )
            ax.set_title(f"{cfg} configuration (seed {first_seed})")
            ax.set_aspect("equal")
            ax.set_xlabel("x (m)")
        axes[0].set_ylabel("y (m)")
        axes[1].legend(loc="upper right", fontsize=8)
        fig.suptitle(f"Fig. {traj_no}: trajectories, Table {table} scenario")
        path = out / f"fig{traj_no}_trajectories_table{table}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)

        fig, axes = plt.subplots(2, 2, figsize=(12, 6.5), sharex=True)
        for col, cfg in enumerate(("paper", "bearings")):
            for fov in sorted({r.cell.fov_deg for r in sel}):
                rs = [r for r in sel if r.cell.config == cfg and r.cell.fov_deg == fov]
                if not rs:
                    continue
                n = min(r.t.size for r in rs)
                t = rs[0].t[:n]
                pos = np.mean([r.pos_err_m[:n] for r in rs], axis=0)
                head = np.mean([r.head_err_deg[:n] for r in rs], axis=0)
                axes[0, col].plot(t, pos, color=COLOURS[fov], lw=1, label=f"{fov:.0f} deg")
                axes[1, col].plot(t, head, color=COLOURS[fov], lw=1)
                if fov == 360.0:
                    bound = _pcrb_of(rs[0], semantic_map)[:n]
                    axes[0, col].plot(t, bound, "k:", lw=1, label="PCRB, 360 deg")
            axes[0, col].set_title(f"{cfg} configuration, mean over seeds")
            axes[0, col].set_yscale("log")
            axes[1, col].set_yscale("log")
            axes[1, col].set_xlabel("time (s)")
        axes[0, 0].set_ylabel("position error (m)")
        axes[1, 0].set_ylabel("heading error (deg)")
        axes[0, 1].legend(fontsize=8)
        fig.suptitle(f"Fig. {err_no}: errors over time, Table {table} scenario")
        path = out / f"fig{err_no}_errors_table{table}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written
