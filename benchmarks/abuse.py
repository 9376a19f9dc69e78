"""Abuse benchmark: one key floods at its full quota, another streams at 10 Hz; how does
the second fare?

Starts `bearings serve` in its own process on a free loopback port with a key file it
writes: key ``heavy`` may hold ``--heavy-sessions`` sessions of ``--heavy-particles``
particles and send ``--heavy-rate`` frames/s in all; key ``light`` holds one session of
``--light-particles``. The heavy key fills its session quota and streams into every
session as fast as its frame quota allows, pipelined (it does not wait for answers);
the light key streams at ``--light-rate`` Hz, one frame at a time, and its answer
latency (send to result) is reported. Bounded: ``--seconds`` of streaming, 127.0.0.1
only.

    python benchmarks/abuse.py --seconds 30
    python benchmarks/abuse.py --seconds 30 --fifo   # steps in arrival order, to compare
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
import websockets

from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate
from benchmarks.load import wait_until_healthy

ROOT = Path(__file__).resolve().parents[1]
HEAVY = "heavy-" + "h" * 32
LIGHT = "light-" + "l" * 32


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(args: argparse.Namespace, keys: Path) -> tuple[str, subprocess.Popen[bytes]]:
    port = free_port()
    env = {
        **os.environ,
        "BEARINGS_MAX_PARTICLES": str(max(args.heavy_particles, args.light_particles)),
        "BEARINGS_FAIR_STEPS": "false" if args.fifo else "true",
    }
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
         "--no-viser", "--log-level", "warning", "--api-keys", str(keys)],
        cwd=ROOT, env=env,
    )  # fmt: skip
    return wait_until_healthy(port, proc), proc


async def create(url: str, key: str, particles: int, seed: int) -> str:
    async with httpx.AsyncClient(base_url=f"http://{url}", timeout=60) as http:
        r = await http.post(
            "/sessions",
            json={"map": "paper_office", "particles": particles, "seed": seed},
            headers={"Authorization": f"Bearer {key}"},
        )
        r.raise_for_status()
        return r.json()["id"]


async def heavy_stream(
    url: str, sid: str, frames: list[str], rate: float, stop: asyncio.Event
) -> dict[str, int]:
    """Send at ``rate`` without waiting for answers; count answers, merges and refusals."""
    counts = {"sent": 0, "answers": 0, "merged": 0, "refused": 0}
    async with websockets.connect(
        f"ws://{url}/sessions/{sid}/stream",
        additional_headers={"Authorization": f"Bearer {HEAVY}"},
        max_size=2**22,
    ) as ws:

        async def read() -> None:
            async for message in ws:
                reply = json.loads(message)
                if "error" in reply:
                    counts["refused"] += 1
                else:
                    counts["answers"] += 1
                    counts["merged"] += any("merged" in w for w in reply["warnings"])

        reader = asyncio.create_task(read())
        start = time.perf_counter()
        while not stop.is_set():
            due = int((time.perf_counter() - start) * rate) + 1
            while counts["sent"] < due:
                await ws.send(frames[counts["sent"] % len(frames)])
                counts["sent"] += 1
            await asyncio.sleep(0.002)
        await asyncio.sleep(1.0)  # let the last answers arrive
        reader.cancel()
    return counts


async def light_stream(
    url: str, sid: str, frames: list[str], rate: float, seconds: float
) -> list[float]:
    """One frame at a time at ``rate`` Hz; the latency of each answer, seconds."""
    latencies = []
    async with websockets.connect(
        f"ws://{url}/sessions/{sid}/stream",
        additional_headers={"Authorization": f"Bearer {LIGHT}"},
        max_size=2**22,
    ) as ws:
        start = next_at = time.perf_counter()
        i = 0
        while time.perf_counter() - start < seconds:
            t0 = time.perf_counter()
            await ws.send(frames[i % len(frames)])
            reply = json.loads(await ws.recv())
            if "error" in reply:
                raise RuntimeError(f"the light client was refused: {reply}")
            latencies.append(time.perf_counter() - t0)
            i += 1
            # The next frame one period after this one was due (or now, if late: a phone
            # drops frames it is late for rather than sending a burst).
            next_at = max(next_at + 1 / rate, time.perf_counter())
            await asyncio.sleep(next_at - time.perf_counter())
    return latencies


async def run(args: argparse.Namespace, url: str) -> dict[str, object]:
    office = load_map(bundled_maps_dir() / "paper_office.json")
    sim = simulate(office, paper_config("nominal", 360), np.random.default_rng(0))
    frames = [json.dumps({k: v for k, v in f.to_contract().items() if k != "truth"}) for f in sim]
    heavy_ids = [
        await create(url, HEAVY, args.heavy_particles, s) for s in range(args.heavy_sessions)
    ]
    light_id = await create(url, LIGHT, args.light_particles, 99)
    # One light answer before the flood, so nothing of its first step is counted.
    await light_stream(url, light_id, frames, args.light_rate, 0.5)
    stop = asyncio.Event()
    heavy = [
        asyncio.create_task(heavy_stream(url, sid, frames, args.heavy_rate / len(heavy_ids), stop))
        for sid in heavy_ids
    ]
    await asyncio.sleep(1.0)  # the flood is on
    latencies = await light_stream(url, light_id, frames, args.light_rate, args.seconds)
    stop.set()
    counts = await asyncio.gather(*heavy) or [{"sent": 0, "answers": 0, "merged": 0, "refused": 0}]
    ms = sorted(1e3 * x for x in latencies)
    q = statistics.quantiles(ms, n=100)
    total = {k: sum(c[k] for c in counts) for k in counts[0]}
    return {
        "scheduling": "fifo" if args.fifo else "fair",
        "seconds": args.seconds,
        "heavy_sessions": args.heavy_sessions,
        "heavy_particles": args.heavy_particles,
        "heavy_rate_quota": args.heavy_rate,
        "heavy_sent_per_s": round(total["sent"] / (args.seconds + 1), 1),
        "heavy_answers_per_s": round(total["answers"] / (args.seconds + 1), 1),
        "heavy_merged_answers": total["merged"],
        "heavy_refused": total["refused"],
        "light_particles": args.light_particles,
        "light_rate_hz": args.light_rate,
        "light_frames": len(ms),
        "light_p50_ms": round(q[49], 1),
        "light_p95_ms": round(q[94], 1),
        "light_max_ms": round(ms[-1], 1),
        "target_p95_ms": 100,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=30.0, help="light streaming time")
    parser.add_argument(
        "--heavy-sessions", type=int, default=4, help="the heavy key's quota (0: no flood)"
    )
    parser.add_argument("--heavy-particles", type=int, default=100_000)
    parser.add_argument(
        "--heavy-rate", type=float, default=200.0, help="the heavy key's frames/s quota"
    )
    parser.add_argument("--light-particles", type=int, default=10_000)
    parser.add_argument("--light-rate", type=float, default=10.0)
    parser.add_argument("--fifo", action="store_true", help="steps in arrival order (no turns)")
    args = parser.parse_args()
    if not 1 <= args.seconds <= 300:
        parser.error("--seconds must be between 1 and 300")
    with tempfile.TemporaryDirectory() as tmp:
        keys = Path(tmp) / "keys.txt"
        keys.write_text(
            f"heavy {HEAVY} {max(1, args.heavy_sessions)} "
            f"{max(1, args.heavy_sessions) * args.heavy_particles} {args.heavy_rate}\n"
            f"light {LIGHT} 1 {args.light_particles} {2 * args.light_rate}\n"
        )
        url, proc = start_server(args, keys)
        try:
            report = asyncio.run(run(args, url))
        finally:
            proc.terminate()
            proc.wait(timeout=60)
    print(json.dumps(report))
    r = report
    print(
        f"{r['scheduling']}: heavy key {r['heavy_sessions']} x {r['heavy_particles']} particles "
        f"offering {r['heavy_sent_per_s']} frames/s ({r['heavy_answers_per_s']} answers/s, "
        f"{r['heavy_merged_answers']} merged, {r['heavy_refused']} refused); light key at "
        f"{r['light_rate_hz']} Hz x {r['light_particles']}: p50 {r['light_p50_ms']} ms, "
        f"p95 {r['light_p95_ms']} ms, max {r['light_max_ms']} ms (target p95 < 100 ms)"
    )


if __name__ == "__main__":
    main()
