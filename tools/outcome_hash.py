"""One hash of everything the service answers over eleven simulated walks.

For a change meant to keep the filter's numbers (a faster form of the same arithmetic):
run this before and after, on the same machine, and compare the two lines. The walks
cover the three bundled maps with 360- and 90-degree cameras, clutter, missed objects,
occlusion, a compass and a kidnap; every frame goes through the service's own path
(``Frame`` validation, ``frame_input``, ``Session.process_sync``), and the hash takes
each frame's whole outcome, each session's final snapshot and its particles' bits.

    python tools/outcome_hash.py

The hash depends on the CPU: numpy picks SIMD versions of cos, exp or arctan2 whose
last bit differs between instruction sets, so compare runs on one machine only.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
from dataclasses import replace

import numpy as np

from app.api.convert import frame_input
from app.api.schemas import Frame
from app.config import Settings
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.store import open_store
from app.service.types import SensorSpec, SessionSpec
from app.simulation.scenarios import paper_config
from app.simulation.simulator import SimulationConfig, simulate
from app.simulation.walks import demo_config
from app.state import to_plain

MAPS = ("paper_office", "office_suite", "two_wing_office")
#: (field of view, occlusion, random misses, false detections per frame) per walk.
FAULTS = ((360.0, False, False, 0.0), (90.0, True, True, 0.5), (360.0, False, True, 1.0))


def walks() -> list[tuple[str, SimulationConfig, float, int]]:
    """(map, walk, camera field of view, seed) of every walk, at most 60 s each."""
    maps = {name: load_map(bundled_maps_dir() / f"{name}.json") for name in MAPS}
    out = []
    for name, semantic_map in maps.items():
        for seed, (fov, occluded, missing, false_rate) in enumerate(FAULTS):
            cfg = demo_config(
                semantic_map,
                np.random.default_rng(seed),
                fov_deg=fov,
                occlusion=occluded,
                missing=missing,
                false_rate=false_rate,
            )
            if seed == 1:
                cfg = replace(cfg, compass_std_deg=5.0)
            if seed == 2 and name == "paper_office":
                cfg = replace(cfg, kidnap_at_s=30.0, kidnap_pose=(3.0, 2.0, 90.0))
            out.append((name, cfg, fov, seed))
    out.append(("paper_office", paper_config("occlusion", 360.0), 360.0, 7))
    out.append(("paper_office", paper_config("missing", 90.0), 90.0, 8))
    return [
        (name, replace(cfg, duration_s=min(cfg.duration_s or 60.0, 60.0)), fov, seed)
        for name, cfg, fov, seed in out
    ]


async def outcome_hash() -> tuple[int, str]:
    """How many frames were stepped, and the hash of what came back."""
    maps = {name: load_map(bundled_maps_dir() / f"{name}.json") for name in MAPS}
    settings = Settings(viser=False, store="memory", max_sessions=100)
    manager = SessionManager(maps, settings, Metrics(), open_store("memory"))
    digest = hashlib.sha256()
    count = 0
    for name, cfg, fov, seed in walks():
        session = await manager.create(
            SessionSpec(
                name, particles=3000 + 1000 * seed, seed=seed, sensor=SensorSpec(fov_deg=fov)
            )
        )
        for sim_frame in simulate(maps[name], cfg, np.random.default_rng(seed)):
            frame = Frame.model_validate_json(json.dumps(sim_frame.to_contract()))
            outcome = session.process_sync(frame_input(frame))
            digest.update(json.dumps(to_plain(outcome), sort_keys=True).encode())
            count += 1
        snapshot = to_plain(session.snapshot())
        snapshot.pop("id")  # random
        digest.update(json.dumps(snapshot, sort_keys=True, default=str).encode())
        pf = session.filter
        for values in (pf.x, pf.y, pf.theta, pf.log_w):
            digest.update(np.ascontiguousarray(values).tobytes())
    return count, digest.hexdigest()


def main() -> None:
    count, digest = asyncio.run(outcome_hash())
    print(f"{count} frames {digest}")


if __name__ == "__main__":
    main()
