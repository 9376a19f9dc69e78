"""`bearings experiments --suite integrity`: is the filter ever confidently wrong?

Every scenario is one map of :mod:`app.experiments.hard_maps` (plus the paper office)
walked under one condition, from a global start, over several seeds. Per scenario:

* **confidently wrong**: share of frames with ``converged`` true and the position more
  than 1 m from the truth (the failure a blind user acts on);
* **availability**: share of frames ``converged`` among the frames whose estimate is
  within 0.5 m of the truth (how often a right answer is also given with confidence);
* **flips per minute**: ``converged`` turning false while the estimate is within 0.3 m
  (confidence lost for nothing), per minute of walk;
* **time to first fix**: median over seeds of the first converged frame's time (a seed
  that never converges counts as infinite);
* **tail error**: 95th percentile of the position error over converged frames;
* **protection coverage**: share of converged frames whose error is within
  ``protection_m``.
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
from app.experiments.hard_maps import BUILDERS, hard_map
from app.experiments.runner import map_jobs
from app.localization.compass import CompassReading
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.simulation.simulator import CompassBias, SimulationConfig, simulate

#: Frames converged yet this far off (m) are confidently wrong.
WRONG_M = 1.0
#: Frames within this distance (m) count for availability.
RIGHT_M = 0.5
#: Losing ``converged`` this close (m) to the truth is a flip.
FLIP_M = 0.3
#: Time of the kidnap (s) in the kidnap condition.
KIDNAP_AT_S = 30.0
#: The two occlusions (s): the whole view blocked for 10 s each.
OCCLUSIONS = ((12.0, 22.0), (36.0, 46.0))

#: Noise of the simulated compass (degrees); the filter is told 20 deg.
COMPASS_STD_DEG = 15.0
COMPASS_TOLD_STD_DEG = 20.0

#: Condition name -> (field of view, simulation changes).
CONDITIONS: dict[str, tuple[float, dict[str, object]]] = {
    "nominal-360": (360.0, {}),
    "nominal-270": (270.0, {}),
    "nominal-180": (180.0, {}),
    "nominal-90": (90.0, {}),
    "clutter-360": (360.0, {"false_rate": 1.0}),
    "clutter-180": (180.0, {"false_rate": 1.0}),
    "missed-180": (180.0, {"miss_prob": 0.3}),
    "occluded-180": (180.0, {"blocked_intervals": OCCLUSIONS, "blocked_sector_deg": 360.0}),
    "kidnap-360": (360.0, {"kidnap_at_s": KIDNAP_AT_S}),
    # The phone's compass (std 15 deg), right, or 60 deg off for 20 s (indoor steel):
    # from the start (while the filter searches) or after the first fix.
    "compass-360": (360.0, {"compass_std_deg": COMPASS_STD_DEG}),
    "compass-180": (180.0, {"compass_std_deg": COMPASS_STD_DEG}),
    "compass-60off-180": (
        180.0,
        {"compass_std_deg": COMPASS_STD_DEG, "compass_biases": (CompassBias(0.0, 20.0, 60.0),)},
    ),
    "compass-60off-late-180": (
        180.0,
        {"compass_std_deg": COMPASS_STD_DEG, "compass_biases": (CompassBias(20.0, 40.0, 60.0),)},
    ),
}
#: Conditions run on every map; the paper office and the rotation room get all.
COMMON = (
    "nominal-360",
    "nominal-180",
    "clutter-180",
    "missed-180",
    "occluded-180",
    "kidnap-360",
    "compass-180",
)
FULL_MAPS = ("paper_office", "rotation_room")
#: The bundled building floor walks 3 minutes: fewer conditions keep the run bounded.
BUILDING_MAP = "two_wing_office"
BUILDING_CONDITIONS = ("nominal-360", "nominal-180", "clutter-180", "kidnap-360")
#: Scenarios of the quick run (development): few, and the hardest.
QUICK = (
    ("rotation_room", "nominal-180"),
    ("rotation_room", "clutter-180"),
    ("paper_office", "nominal-360"),
    ("door_corridor", "nominal-180"),
    ("two_wings", "kidnap-360"),
    ("symmetric_room", "compass-60off-180"),
)


@dataclass(frozen=True)
class Scenario:
    map_name: str
    condition: str

    @property
    def name(self) -> str:
        return f"{self.map_name} / {self.condition}"

    @property
    def fov_deg(self) -> float:
        return CONDITIONS[self.condition][0]

    def simulation(self) -> SimulationConfig:
        hm = hard_map(self.map_name)
        fov, changes = CONDITIONS[self.condition]
        sim = SimulationConfig(
            path=hm.path,
            fov_deg=fov,
            bearing_noise_deg=2.0,
            odometry_noise_m=0.02,
            odometry_noise_deg=1.0,
        )
        sim = replace(sim, **changes)  # type: ignore[arg-type]
        if self.condition.startswith("kidnap"):
            sim = replace(sim, kidnap_pose=hm.kidnap_pose, kidnap_at_s=hm.kidnap_at_s)
        return sim


def scenarios(quick: bool = False, select: str | None = None) -> list[Scenario]:
    """Every scenario of the suite, in a stable order.

    ``select``: comma-separated ``MAP`` or ``MAP/CONDITION`` (``*`` for any map): only
    those of the suite's scenarios.
    """
    if quick:
        return [Scenario(m, c) for m, c in QUICK]
    out = []
    for name in BUILDERS:
        conds = tuple(CONDITIONS) if name in FULL_MAPS else COMMON
        if name == BUILDING_MAP:
            conds = BUILDING_CONDITIONS
        out += [Scenario(name, c) for c in conds]
    if select is None:
        return out
    wanted = [w.strip().split("/", 1) for w in select.split(",") if w.strip()]
    for w in wanted:
        if w[0] != "*" and w[0] not in BUILDERS:
            raise ValueError(f"--scenarios: unknown map {w[0]!r}; maps: {', '.join(BUILDERS)}")
        if len(w) == 2 and w[1] not in CONDITIONS:
            raise ValueError(
                f"--scenarios: unknown condition {w[1]!r}; conditions: {', '.join(CONDITIONS)}"
            )

    def chosen(s: Scenario) -> bool:
        return any(
            w[0] in ("*", s.map_name) and (len(w) == 1 or w[1] == s.condition) for w in wanted
        )

    return [s for s in out if chosen(s)]


@dataclass(frozen=True)
class IntegrityRun:
    """One seed of one scenario: per-frame arrays, each shape (T,)."""

    scenario: Scenario
    seed: int
    t: np.ndarray
    err_m: np.ndarray
    converged: np.ndarray
    protection_m: np.ndarray  # nan where None
    step_ms: np.ndarray


def run_scenario(scenario: Scenario, seed: int, particles: int) -> IntegrityRun:
    """Simulate one walk and run the service's filter over it from a global start."""
    hm = hard_map(scenario.map_name)
    world_rng, filter_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence([seed, 12]).spawn(2)
    )
    frames = simulate(hm.map, scenario.simulation(), world_rng)
    config = FilterConfig(particles=particles, fov_deg=scenario.fov_deg)
    pf = ParticleFilter(hm.map, config, rng=filter_rng)
    n = len(frames)
    err = np.empty(n)
    conv = np.zeros(n, dtype=bool)
    prot = np.full(n, np.nan)
    ms = np.empty(n)
    for i, f in enumerate(frames):
        t0 = time.perf_counter()
        heading = None
        if f.compass_rad is not None:
            heading = CompassReading(f.compass_rad, np.radians(COMPASS_TOLD_STD_DEG))
        e = pf.step(f.odometry, f.detections, heading)
        ms[i] = (time.perf_counter() - t0) * 1e3
        err[i] = np.hypot(e.x - f.truth.x, e.y - f.truth.y)
        conv[i] = e.converged
        if e.protection_m is not None:
            prot[i] = e.protection_m
    t = np.array([f.t for f in frames])
    return IntegrityRun(scenario, seed, t, err, conv, prot, ms)


def _job(args: tuple[Scenario, int, int]) -> IntegrityRun:
    return run_scenario(*args)


def run_suite(
    todo: list[Scenario],
    seeds: int,
    particles: int,
    workers: int,
    progress: Callable[[], object] | None = None,
) -> list[IntegrityRun]:
    jobs = [(s, seed, particles) for s in todo for seed in range(seeds)]
    return map_jobs(_job, jobs, workers, progress)


def flips(run: IntegrityRun) -> int:
    """How often ``converged`` turned false while the estimate was within FLIP_M."""
    c = run.converged
    lost = np.flatnonzero(c[:-1] & ~c[1:]) + 1
    return int(np.sum(run.err_m[lost] <= FLIP_M))


def first_fix_s(run: IntegrityRun) -> float:
    hit = np.flatnonzero(run.converged)
    return float(run.t[hit[0]]) if hit.size else float("inf")


def metrics(runs: list[IntegrityRun]) -> dict[str, float | int]:
    """The suite's figures over the given runs (pooled over their frames)."""
    err = np.concatenate([r.err_m for r in runs])
    conv = np.concatenate([r.converged for r in runs])
    prot = np.concatenate([r.protection_m for r in runs])
    right = err <= RIGHT_M
    minutes = sum(float(r.t[-1] - r.t[0]) + 0.2 for r in runs) / 60.0
    covered = conv & (err <= np.nan_to_num(prot, nan=-1.0))
    fixes = [first_fix_s(r) for r in runs]
    return {
        "seeds": len(runs),
        "frames": int(err.size),
        "converged_frames": int(conv.sum()),
        "wrong_frames": int(np.sum(conv & (err > WRONG_M))),
        "wrong_share": float(np.mean(conv & (err > WRONG_M))),
        "availability": float(conv[right].mean()) if right.any() else float("nan"),
        "flips_per_min": sum(flips(r) for r in runs) / minutes,
        "median_first_fix_s": float(np.median(fixes)),
        "never_fixed": int(np.sum(~np.isfinite(fixes))),
        "tail_err_m": float(np.percentile(err[conv], 95)) if conv.any() else float("nan"),
        "coverage": float(covered.sum() / conv.sum()) if conv.any() else float("nan"),
        # How much of the radius the truth needs: its 99th percentile calibrates it.
        "error_over_radius_p99": float(np.percentile(err[conv] / prot[conv], 99))
        if conv.any()
        else float("nan"),
        "median_protection_m": float(np.median(prot[conv])) if conv.any() else float("nan"),
        "median_step_ms": float(np.median(np.concatenate([r.step_ms for r in runs]))),
    }


def summarize(runs: list[IntegrityRun]) -> dict[str, object]:
    by: dict[Scenario, list[IntegrityRun]] = defaultdict(list)
    for r in runs:
        by[r.scenario].append(r)
    rows = []
    for s, rs in by.items():
        row: dict[str, object] = {"map": s.map_name, "condition": s.condition}
        row.update(metrics(rs))
        rows.append(row)
    return {"scenarios": rows, "total": metrics(runs)}


def format_cell(v: object, fmt: str) -> str:
    """A table cell: ``v`` formatted, "-" for a NaN (no such frame), "never" for inf."""
    if isinstance(v, float) and not np.isfinite(v):
        return "-" if np.isnan(v) else "never"
    return format(v, fmt)


def markdown_table(summary: dict[str, object]) -> str:
    """The per-scenario table (also pasted into the README)."""
    cell = format_cell
    lines = [
        "| map | condition | confidently wrong | availability | flips / min | first fix (s) "
        "| tail error p95 (m) | protection coverage |",
        "|---|---|---|---|---|---|---|---|",
    ]
    scenario_rows = summary["scenarios"]
    total = summary["total"]
    assert isinstance(scenario_rows, list) and isinstance(total, dict)
    rows = [*scenario_rows, dict(total, map="**all**", condition="")]
    for row in rows:
        lines.append(
            f"| {row['map']} | {row['condition']} "
            f"| {row['wrong_frames']} / {row['frames']} "
            f"({cell(100 * row['wrong_share'], '.2f')} %) "
            f"| {cell(row['availability'], '.2f')} | {cell(row['flips_per_min'], '.2f')} "
            f"| {cell(row['median_first_fix_s'], '.1f')} | {cell(row['tail_err_m'], '.3f')} "
            f"| {cell(row['coverage'], '.3f')} |"
        )
    return "\n".join(lines)


def markdown(summary: dict[str, object], *, seconds: float, particles: int, seeds: int) -> str:
    total = summary["total"]
    assert isinstance(total, dict)
    return "\n".join(
        [
            "# Integrity suite: never confidently wrong, steadily confident when right",
            "",
            f"Generated by `bearings experiments --suite integrity` in {seconds:.0f} s: "
            f"{seeds} seeds per scenario, up to {particles} particles (adaptive), global "
            "start, 5 frames/s, 0.5 m/s, bearing noise 2 deg, odometry noise 2 cm and 1 deg "
            "per frame, camera range 15 m. Maps: `app/experiments/hard_maps.py`; conditions "
            "and metrics: `app/experiments/integrity.py`.",
            "",
            machine_line(),
            "",
            f"* confidently wrong: converged and more than {WRONG_M:g} m off (frames, share)",
            f"* availability: share of frames converged among those within {RIGHT_M:g} m",
            f"* flips: converged -> not converged while within {FLIP_M:g} m, per minute",
            "* first fix: median over seeds of the first converged frame ('never' when half "
            "the seeds never converge)",
            "* tail error: 95th percentile of the error over converged frames",
            "* protection coverage: share of converged frames with the error within `protection_m`",
            "",
            "Conditions: `clutter` one false detection per frame (Poisson), `missed` each "
            "object missed with probability 0.3, `occluded` the whole view blocked at "
            f"{OCCLUSIONS[0][0]:g}-{OCCLUSIONS[0][1]:g} s and {OCCLUSIONS[1][0]:g}-"
            f"{OCCLUSIONS[1][1]:g} s, `kidnap` carried elsewhere at {KIDNAP_AT_S:g} s "
            "(on the bundled `two_wing_office` floor: the building suite's 3-minute walk and "
            "its kidnap between the wings).",
            "",
            markdown_table(summary),
            "",
            f"Median step time over all frames: {total['median_step_ms']:.2f} ms.",
            "",
        ]
    )


def figure(runs: list[IntegrityRun], summary: dict[str, object], out: Path) -> Path:
    """Bars per scenario (wrong share, availability, flips) and one rotation-room walk."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = summary["scenarios"]
    assert isinstance(rows, list)
    labels = [f"{r['map']}\n{r['condition']}" for r in rows]
    fig, axes = plt.subplots(4, 1, figsize=(max(10, 0.45 * len(rows)), 13))
    xs = np.arange(len(rows))
    axes[0].bar(xs, [100 * r["wrong_share"] for r in rows], color="tab:red")
    axes[0].set_ylabel("confidently wrong (%)")
    axes[1].bar(xs, [r["availability"] for r in rows], color="tab:green")
    axes[1].set_ylabel("availability")
    axes[1].set_ylim(0, 1)
    axes[2].bar(xs, [r["flips_per_min"] for r in rows], color="tab:orange")
    axes[2].axhline(1.0, color="k", lw=0.8, ls=":")
    axes[2].set_ylabel("flips / min")
    for ax in axes[:3]:
        ax.set_xticks(xs, labels if ax is axes[2] else [], rotation=90, fontsize=7)
    pick = [r for r in runs if r.scenario == Scenario("rotation_room", "nominal-180")]
    ax = axes[3]
    if pick:
        r = pick[0]
        ax.plot(r.t, r.err_m, color="k", lw=1, label="position error")
        ax.plot(r.t, r.protection_m, color="tab:blue", lw=1, label="protection_m")
        ax.fill_between(
            r.t, 0, 1, where=r.converged, transform=ax.get_xaxis_transform(),
            color="tab:green", alpha=0.15, label="converged",
        )  # fmt: skip
        ax.set_yscale("log")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("m")
        ax.set_title(f"rotation_room / nominal-180, seed {r.seed}")
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "integrity.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def run(
    out: Path, *, seeds: int, particles: int, workers: int, quick: bool, select: str | None = None
) -> dict[str, object]:
    """Run the suite (or the ``select`` scenarios), write integrity.md/.json and the figure;
    return the summary."""
    from tqdm import tqdm

    todo = scenarios(quick, select)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    with tqdm(total=len(todo) * seeds, desc="integrity runs", unit="run") as bar:
        runs = run_suite(todo, seeds, particles, workers, bar.update)
    seconds = time.perf_counter() - started
    summary = summarize(runs)
    (out / "integrity.json").write_text(json.dumps(summary, indent=1), encoding="utf-8")
    text = markdown(summary, seconds=seconds, particles=particles, seeds=seeds)
    if select is not None:
        text = text.replace("--suite integrity`", f"--suite integrity --scenarios '{select}'`", 1)
    (out / "integrity.md").write_text(text, encoding="utf-8")
    figure(runs, summary, out)
    return summary
