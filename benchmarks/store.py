"""What a session store costs one worker per frame, without HTTP or WebSockets.

Runs the service's own frame path (``SessionManager.process``: the fair stepper, the
session pumps and, with ``--store redis://...``, the journal, the checkpoints and the
leases) on an event loop (uvloop, as ``bearings serve``), for ``--sessions`` sessions
walking the paper office, each sending its next frame as soon as the last is answered.
Prints the process's CPU per frame, and with Redis how many entries each journal write
carried. Without the network layer's cost and noise, differences of a few per cent
between stores (or versions) show in a few runs; compare runs taken alternately.

    python benchmarks/store.py --store memory
    python benchmarks/store.py --store redis://127.0.0.1:6379/0
    python benchmarks/store.py --store redis://127.0.0.1:6379/0 --checkpoint-interval 1000

Pin it to a core (``taskset -c 0``) with Redis on the other, for steadier figures.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import time
from dataclasses import replace

import numpy as np
import uvloop

import app.service.store.writer as writer_module
from app.api.convert import frame_input
from app.api.schemas import Frame
from app.config import Settings
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.store import Hold, open_store
from app.service.store.group_commit import Entry
from app.service.types import FrameInput, SessionSpec
from app.simulation.scenarios import PAPER_PATH, paper_config
from app.simulation.simulator import simulate


def walk_frames() -> list[FrameInput]:
    """The paper office there and back, as the API would hand the frames to the service."""
    office = load_map(bundled_maps_dir() / "paper_office.json")
    there_and_back = PAPER_PATH + PAPER_PATH[-2::-1] + PAPER_PATH[1:]
    config = replace(paper_config("nominal", 360), path=there_and_back)
    frames = simulate(office, config, np.random.default_rng(0))
    return [frame_input(Frame.model_validate_json(json.dumps(f.to_contract()))) for f in frames]


async def run(args: argparse.Namespace) -> None:
    frames = walk_frames()
    office = load_map(bundled_maps_dir() / "paper_office.json")
    settings = Settings(
        viser=False,
        store=args.store,
        max_sessions=max(args.sessions, 1),
        checkpoint_interval_s=args.checkpoint_interval,
    )
    writes = {"calls": 0, "entries": 0}
    if args.store != "memory":  # count the journal's writes (and their entries)
        write = writer_module.LoopWriter._write

        async def counted(self: writer_module.LoopWriter, batch: list[Entry]) -> list[Hold]:
            writes["calls"] += 1
            writes["entries"] += len(batch)
            return await write(self, batch)

        writer_module.LoopWriter._write = counted  # type: ignore[method-assign]
    manager = SessionManager({"paper_office": office}, settings, Metrics(), open_store(args.store))
    keeper = asyncio.create_task(manager.sharing.run_keeper()) if manager.sharing else None
    sessions = [
        await manager.create(SessionSpec("paper_office", particles=args.particles, seed=s))
        for s in range(args.sessions)
    ]
    starts = [(s * 7) % (len(frames) - args.warmup - args.frames) for s in range(args.sessions)]

    async def walk(k: int, first: int, last: int) -> None:
        for i in range(first, last):
            await manager.process(sessions[k].id, frames[starts[k] + i])

    # Every session converges first; only the converged walk is measured.
    await asyncio.gather(*(walk(k, 0, args.warmup) for k in range(args.sessions)))
    before = dict(writes)
    cpu, wall = time.process_time(), time.perf_counter()
    end = args.warmup + args.frames
    await asyncio.gather(*(walk(k, args.warmup, end) for k in range(args.sessions)))
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    n = args.sessions * args.frames
    line = f"{args.store}: {1e3 * cpu / n:.3f} ms CPU per frame, {n / wall:.0f} frames/s"
    if args.store != "memory":
        calls = writes["calls"] - before["calls"]
        line += f", {(writes['entries'] - before['entries']) / max(calls, 1):.1f} entries a write"
    print(line)
    if keeper is not None:
        keeper.cancel()
    if manager.sharing is not None:
        await manager.sharing.shutdown()
        manager.sharing.close()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--store", default="memory", help="memory or redis://HOST:PORT/DB")
    parser.add_argument("--sessions", type=int, default=120)
    parser.add_argument("--frames", type=int, default=40, help="measured frames per session")
    parser.add_argument("--warmup", type=int, default=30, help="frames per session first")
    parser.add_argument("--particles", type=int, default=10_000)
    parser.add_argument(
        "--checkpoint-interval", type=float, default=1.0,
        help="seconds between checkpoints (1000: none while measuring)",
    )  # fmt: skip
    uvloop.run(run(parser.parse_args()))


if __name__ == "__main__":
    main()
