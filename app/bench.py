"""`bearings bench`: time one full filter step on a generated map.

The map is a walled floor (a grid of rooms with door gaps) with ``--objects``
objects over three classes; each step predicts with a small odometry step, corrects
with ``--detections`` detections (visibility on), estimates and resamples when due.
Compilation and the visibility grid are built before timing starts.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from dataclasses import asdict

import numpy as np

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter, warm_up
from app.localization.types import Detection, Odometry
from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import ensure_prepared

CLASSES = ("door", "window", "table")


def generated_map(n_objects: int, seed: int = 0) -> SemanticMap:
    """A 20 m x 12 m floor split into 4 x 2 rooms, with ``n_objects`` over 3 classes,
    prepared (its grids built)."""
    rng = np.random.default_rng(seed)
    w, h = 20.0, 12.0
    walls = [
        {"x1": 0, "y1": 0, "x2": w, "y2": 0},
        {"x1": w, "y1": 0, "x2": w, "y2": h},
        {"x1": w, "y1": h, "x2": 0, "y2": h},
        {"x1": 0, "y1": h, "x2": 0, "y2": 0},
    ]
    for x in (5.0, 10.0, 15.0):  # inner walls with a 1 m gap (doorway) in each room
        walls += [
            {"x1": x, "y1": 0, "x2": x, "y2": 2.5},
            {"x1": x, "y1": 3.5, "x2": x, "y2": 8.5},
            {"x1": x, "y1": 9.5, "x2": x, "y2": h},
        ]
    walls += [{"x1": 0, "y1": 6, "x2": 2, "y2": 6}, {"x1": 3, "y1": 6, "x2": w, "y2": 6}]
    objects = [
        {
            "class": CLASSES[i % 3],
            "x": float(rng.uniform(0.3, w - 0.3)),
            "y": float(rng.uniform(0.3, h - 0.3)),
        }
        for i in range(n_objects)
    ]
    return ensure_prepared(parse_map({"name": "bench", "walls": walls, "objects": objects}))


def cpu_model() -> str:
    """The CPU's model name, for the record."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def kernel_target() -> str:
    """The CPU the compiled kernels are built for (``NUMBA_CPU_NAME`` when set, else the
    host's as LLVM names it): float32 results, and so a walk's particles, can differ in
    the last bits between targets, and a marginal walk's outcome with them."""
    name = os.environ.get("NUMBA_CPU_NAME")
    if name:
        return name
    from llvmlite import binding

    return str(binding.get_host_cpu_name())


def machine_line() -> str:
    """One line for a results file: the CPU and the kernels' target."""
    return f"Machine: {cpu_model()}; compiled kernels built for `{kernel_target()}`."


def bench_step(
    particles: int, detections: int, objects: int, steps: int, seed: int = 0
) -> dict[str, object]:
    """Time ``steps`` full steps; return the figures as a dict (milliseconds)."""
    semantic_map = generated_map(objects, seed)
    config = FilterConfig(particles=particles, adaptive=False)
    rng = np.random.default_rng(seed)
    pf = ParticleFilter(semantic_map, config, rng=rng)
    det_rng = np.random.default_rng(seed + 1)
    frames = [
        [
            Detection(CLASSES[k % 3], float(det_rng.uniform(-np.pi, np.pi)), 0.9)
            for k in range(detections)
        ]
        for _ in range(8)
    ]
    odo = Odometry(0.1, 0.0, np.radians(2.0))
    for i in range(3):  # warm caches
        pf.step(odo, frames[i % len(frames)])
    times = np.empty(steps)
    for i in range(steps):
        t0 = time.perf_counter()
        pf.step(odo, frames[i % len(frames)])
        times[i] = time.perf_counter() - t0
    ms = times * 1e3
    return {
        "median_ms_per_step": round(float(np.median(ms)), 3),
        "p90_ms_per_step": round(float(np.percentile(ms, 90)), 3),
        "min_ms_per_step": round(float(ms.min()), 3),
        "steps": steps,
        "particles": particles,
        "detections": detections,
        "objects": objects,
        "walls": int(semantic_map.walls.shape[0]),
        "cpu": cpu_model(),
        "config": {k: v for k, v in asdict(config).items() if k != "class_bearing_std_deg"},
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--particles", type=int, default=10_000, help="particles (default 10000)")
    parser.add_argument(
        "--detections", type=int, default=10, help="detections per frame over 3 classes"
    )
    parser.add_argument("--objects", type=int, default=30, help="objects on the generated map")
    parser.add_argument("--steps", type=int, default=200, help="timed steps (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    for name in ("particles", "detections", "objects", "steps"):
        if getattr(args, name) < 1:
            raise SystemExit(f"bearings bench: --{name} must be at least 1")
    warm_up()
    result = bench_step(args.particles, args.detections, args.objects, args.steps, args.seed)
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"{result['median_ms_per_step']:.2f} ms median per step "
            f"(p90 {result['p90_ms_per_step']:.2f} ms) over {result['steps']} steps: "
            f"{args.particles} particles, {args.detections} detections, "
            f"{args.objects} objects, {result['walls']} walls; {result['cpu']}"
        )
    return 0
