"""Map loading and session figures (issue 13): preparation, cache, start-up, sessions, steps.

    python benchmarks/maps.py            # everything, medians of --repeats runs
    python benchmarks/maps.py --json
    python benchmarks/maps.py --only startup --repeats 10   # one part (repeatable flag)
    python benchmarks/maps.py --only startup --repeats 10 --against ../main  # old vs new

Measures, on this machine:

1. **Preparation** of each bundled map (free-space + visibility grids, no cache) and of a
   denser synthetic floor the size of issue 13's (~250 walls, ~130 objects: the
   bundled two-wing floor with desk partitions added), and reading them back from the
   disk cache.
2. **Session creation** at 10,000 particles on every bundled map (what
   ``POST /sessions`` runs off the event loop: filter + narrator on a prepared map).
3. **Server start to first session**: ``bearings serve`` in its own process, timed from
   launch to the first ``201`` of ``POST /sessions`` on ``two_wing_office``; cold (empty
   map cache) and warm (cache filled by the cold run). Compiled kernels come from
   numba's own disk cache in both (as after a Docker build).
4. **Filter step** median on a simulated walk with 10,000 particles (adaptive count off,
   so both maps do the same work per step): the paper office (paper path) against the
   two-wing floor (the building suite's walk).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np

from app.config import Settings
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter, warm_up
from app.maps.check import load_map
from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import build, prepare
from app.resources import bundled_maps_dir
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.types import SessionSpec
from app.simulation.simulator import SimulationConfig, simulate


def dense_floor() -> SemanticMap:
    """The two-wing floor plus desk partitions: ~250 walls and ~130 objects."""
    data = load_map(bundled_maps_dir() / "two_wing_office.json").to_json()
    walls = list(data["walls"])  # type: ignore[arg-type]
    objects = list(data["objects"])  # type: ignore[arg-type]
    rng = np.random.default_rng(3)
    # Partitions 1.2 m long in rows across every room (not touching the room walls).
    for x0 in (0.0, 21.0):
        for i in range(3):
            a = x0 + i * 17.0 / 3.0
            for y0, y1 in ((1.5, 9.5), (14.5, 22.5)):
                for y in np.arange(y0, y1, 1.3):
                    for xa in (a + 0.9, a + 3.2):
                        xa += float(rng.uniform(-0.1, 0.1))
                        walls.append({"x1": xa, "y1": float(y), "x2": xa + 1.2, "y2": float(y)})
    while len(objects) < 133:
        objects.append(
            {"class": "chair", "x": float(rng.uniform(1, 37)), "y": float(rng.uniform(11.4, 12.6))}
        )
    data.update(name="dense_floor", walls=walls, objects=objects)
    return parse_map(data)


def median_time(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench_prepare(repeats: int) -> list[dict[str, object]]:
    rows = []
    maps = {p.stem: (lambda p=p: load_map(p)) for p in sorted(bundled_maps_dir().glob("*.json"))}
    maps["dense_floor (issue-13 size)"] = dense_floor
    build(dense_floor())  # compile the kernels (numba caches them on disk)
    for name, make in maps.items():
        m = make()
        fresh = iter([make() for _ in range(repeats)])
        built = median_time(lambda fresh=fresh: build(next(fresh)), repeats)
        with tempfile.TemporaryDirectory() as tmp:
            prepare(m, Path(tmp))
            again = iter([make() for _ in range(repeats)])
            cached = median_time(
                lambda again=again, tmp=tmp: prepare(next(again), Path(tmp)), repeats
            )
        fs = m.free_space
        rows.append(
            {
                "map": name,
                "walls": int(m.walls.shape[0]),
                "objects": m.object_count,
                "free_m2": round(float(fs.free_cells.size * fs.resolution_m**2), 1),
                "grid_cells": int(fs.mask.size),
                "build_s": round(built, 3),
                "cached_s": round(cached, 4),
            }
        )
    return rows


def bench_sessions(repeats: int) -> list[dict[str, object]]:
    from app.main import load_maps

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(viser=False, cache_dir=Path(tmp))
        maps = load_maps(settings)
        manager = SessionManager(maps, settings, Metrics())
        rows = []
        for name in maps:
            spec = SessionSpec(map_name=name, particles=10_000, seed=1)
            manager.build(spec)  # the work of POST /sessions, off the loop
            t = median_time(lambda spec=spec: manager.build(spec), repeats)
            rows.append({"map": name, "create_ms": round(1e3 * t, 2)})
        manager.close()
    return rows


#: This checkout (the server timed unless ``--against`` names another one too).
ROOT = Path(__file__).resolve().parents[1]


def _byte_compile_app(tree: Path) -> None:
    """Write the app's bytecode, as ``pip install`` does for an installed service.

    A shell with ``PYTHONDONTWRITEBYTECODE`` set (this project's VM) never writes it, so
    every timed start would otherwise compile about a hundred modules from source (about
    0.1 s). Files already compiled are only checked.
    """
    import compileall

    compileall.compile_dir(tree / "app", quiet=1)


def _start_to_first_session(cache_dir: Path, tree: Path = ROOT) -> float:
    """Seconds from launching ``bearings serve`` (the checkout ``tree``) to the first 201."""
    from tests.helpers import free_port

    _byte_compile_app(tree)
    port = free_port()
    env = {**os.environ, "BEARINGS_CACHE_DIR": str(cache_dir)}
    # One client for every try: a fresh httpx.post per try costs ~25 ms of CPU (a new SSL
    # context each time), which on 2 cores was taken from the server being timed.
    with httpx.Client(timeout=5) as client:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--no-viser",
             "--log-level", "warning"],
            env=env,
            cwd=tree,
        )  # fmt: skip
        try:
            deadline = t0 + 120
            while time.perf_counter() < deadline:
                try:
                    r = client.post(
                        f"http://127.0.0.1:{port}/sessions",
                        json={"map": "two_wing_office", "particles": 10_000},
                    )
                    if r.status_code == 201:
                        return time.perf_counter() - t0
                except httpx.TransportError:
                    pass
                time.sleep(0.01)
            raise RuntimeError("the server did not answer within 120 s")
        finally:
            proc.terminate()
            proc.wait(timeout=30)


def bench_startup(repeats: int, against: Path | None = None) -> dict[str, object]:
    """Cold (empty map cache) then warm (the cache that run filled) starts, ``repeats``
    times; with ``against``, that checkout's server too, interleaved run by run so both
    see the same machine load (its numba cache must be warm: run it once beforehand)."""
    trees = {"this": ROOT} | ({"against": against.resolve()} if against else {})
    runs: dict[str, dict[str, list[float]]] = {k: {"cold": [], "warm": []} for k in trees}
    for i in range(repeats):
        for name in list(trees)[:: 1 if i % 2 == 0 else -1]:
            with tempfile.TemporaryDirectory() as tmp:
                runs[name]["cold"].append(_start_to_first_session(Path(tmp), trees[name]))
                runs[name]["warm"].append(_start_to_first_session(Path(tmp), trees[name]))
    out: dict[str, object] = {}
    for name, r in runs.items():
        prefix = "" if name == "this" else "against_"
        out |= {
            f"{prefix}cold_s": round(statistics.median(r["cold"]), 2),
            f"{prefix}warm_s": round(statistics.median(r["warm"]), 2),
            f"{prefix}cold_runs": [round(v, 2) for v in r["cold"]],
            f"{prefix}warm_runs": [round(v, 2) for v in r["warm"]],
        }
    return out


def _walk_steps_ms(semantic_map: SemanticMap, sim: SimulationConfig, seed: int) -> list[float]:
    frames = simulate(semantic_map, sim, np.random.default_rng(seed))
    config = FilterConfig(particles=10_000, adaptive=False)
    pf = ParticleFilter(semantic_map, config, rng=np.random.default_rng(seed))
    out = []
    for f in frames:
        t0 = time.perf_counter()
        pf.step(f.odometry, f.detections)
        out.append(1e3 * (time.perf_counter() - t0))
    return out


def bench_steps(seeds: int) -> dict[str, object]:
    from app.experiments.building import simulation
    from app.simulation.scenarios import paper_config

    warm_up()
    office = load_map(bundled_maps_dir() / "paper_office.json")
    floor = load_map(bundled_maps_dir() / "two_wing_office.json")
    a, b = [], []
    for seed in range(seeds):  # interleaved, so both see the same machine load
        a += _walk_steps_ms(office, paper_config("nominal", 360.0), seed)
        b += _walk_steps_ms(floor, simulation("nominal-360"), seed)
    pa, pb = statistics.median(a), statistics.median(b)
    return {
        "paper_office_ms": round(pa, 3),
        "two_wing_office_ms": round(pb, 3),
        "ratio": round(pb / pa, 2),
        "paper_office_p99_ms": round(float(np.percentile(a, 99)), 2),
        "two_wing_office_p99_ms": round(float(np.percentile(b, 99)), 2),
        "two_wing_office_max_ms": round(max(b), 1),
    }


#: The parts ``--only`` can pick.
PARTS = ("prepare", "sessions", "startup", "steps")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seeds", type=int, default=2, help="walks per map for the step")
    parser.add_argument("--skip-startup", action="store_true")
    parser.add_argument(
        "--only",
        action="append",
        choices=PARTS,
        help="run only this part (repeatable); startup runs --repeats cold/warm pairs then",
    )
    parser.add_argument(
        "--against",
        type=Path,
        metavar="CHECKOUT",
        help="also time the start-up of another checkout's server (e.g. a worktree of "
        "main), interleaved with this one's",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    parts = set(args.only or PARTS) - ({"startup"} if args.skip_startup else set())
    out: dict[str, object] = {}
    if "prepare" in parts:
        out["prepare"] = bench_prepare(args.repeats)
    if "sessions" in parts:
        out["sessions"] = bench_sessions(max(args.repeats, 20))
    if "startup" in parts:
        repeats = args.repeats if args.only else max(1, args.repeats // 2)
        out["startup"] = bench_startup(repeats, args.against)
    if "steps" in parts:
        out["steps"] = bench_steps(args.seeds)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    if "prepare" in out:
        print("preparation (free space + visibility), median s:")
        for r in out["prepare"]:  # type: ignore[union-attr]
            print(
                f"  {r['map']:28s} {r['walls']:4d} walls {r['objects']:4d} objects "
                f"{r['free_m2']:7.1f} m2 free: build {r['build_s']:.3f} s, "
                f"cache {r['cached_s']:.4f} s"
            )
    if "sessions" in out:
        print("session creation at 10,000 particles, median ms:")
        for r in out["sessions"]:  # type: ignore[union-attr]
            print(f"  {r['map']:28s} {r['create_ms']:.2f} ms")
    if "startup" in out:
        print(f"server start to first session: {out['startup']}")
    if "steps" in out:
        print(f"filter step, median ms: {out['steps']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
