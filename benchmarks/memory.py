"""Memory one session keeps between frames (issue 8 target: at most 1 MB at 10,000 particles).

Per-map structures (the visibility grid, the free-space grid) are shared by every
session on that map and built before measuring; what is left is the session's own:
the particle arrays, the filter's and narrator's state, the last result.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import tracemalloc

import numpy as np

from app.api.schemas import Frame, SessionCreate
from app.config import Settings
from app.maps.check import load_map_dir
from app.resources import bundled_maps_dir
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate


async def measure(particles: int, frames: int) -> dict[str, float]:
    maps = load_map_dir(bundled_maps_dir())
    office = maps["paper_office"]
    _ = office.visibility
    _ = office.free_space
    manager = SessionManager(maps, Settings(viser=False, max_particles=10**6), Metrics())
    sim = [
        Frame.model_validate(f.to_contract())
        for f in simulate(office, paper_config(), np.random.default_rng(0))
    ]
    warm = await manager.create(SessionCreate(map="paper_office", particles=particles, seed=0))
    for f in sim[:frames]:  # warm every code path once, outside the measurement
        await manager.process(warm.id, f)
    gc.collect()
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    s = await manager.create(SessionCreate(map="paper_office", particles=particles, seed=1))
    created = tracemalloc.get_traced_memory()[0]
    peak_step = 0
    for f in sim[:frames]:
        tracemalloc.reset_peak()
        await manager.process(s.id, f)
        peak_step = max(peak_step, tracemalloc.get_traced_memory()[1])
    gc.collect()
    after = tracemalloc.take_snapshot()
    kept = sum(stat.size_diff for stat in after.compare_to(before, "filename"))
    tracemalloc.stop()
    pf = s.filter
    arrays = pf.x.nbytes + pf.y.nbytes + pf.theta.nbytes + pf.log_w.nbytes
    return {
        "particles": particles,
        "frames": frames,
        "particles_now": pf.n,
        "particle_arrays_bytes": arrays,
        "kept_after_frames_bytes": kept,
        "kept_just_created_bytes": created,
        "transient_peak_during_a_step_bytes": peak_step,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--particles", type=int, default=10_000)
    parser.add_argument("--frames", type=int, default=50)
    args = parser.parse_args()
    r = asyncio.run(measure(args.particles, args.frames))
    for k, v in r.items():
        print(f"{k}: {v:,}")


if __name__ == "__main__":
    main()
