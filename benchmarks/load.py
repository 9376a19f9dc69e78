"""Load test: N WebSocket sessions streaming frames at R Hz for T seconds.

Starts a real server on a free loopback port (or uses ``--url``, e.g. a proxy in front
of several workers), creates N sessions, streams simulated paper-office frames at the
given rate from each, and reports p50/p95/max latency (send to result), frames/s and
errors; for a server it started, also the server's CPU seconds per 1,000 frames (from
/proc, less sensitive to other load on the machine than latency is), over the whole run
and over the steady window (below).

Two throughputs: ``frames_per_s`` over the whole run (creating the sessions, their first
seconds of global localization at the full particle count, closing them), and
``steady_frames_per_s``, the frames sent after ``--warmup`` seconds of each session
divided by the time left: what the server sustains for converged walks. The steady
window for the server's CPU (``steady_server_cpu_s_per_1000_frames``) runs from
``--stagger`` + ``--warmup`` seconds after the start, when every session is past its
warm-up, to ``--seconds`` after it, before the first one ends: the CPU spent then over
the answers received then. It leaves out creating the sessions and their global
localization, so it compares two stores, or two versions, best. The generator's
own CPU share is reported too (``client_cpu_share``): near 1.0, the latencies are partly
the generator's.

Clients send at their own phase of the period, as independent phones would; with
``--stagger S`` they also start their sessions at their own moments within S seconds.
Started together, every session's filter converges on the same frame, and its global
consistency searches (every 25 frames once nothing is found) then fall on the same
frames in every session: with 100 sessions started at once, the frames answered in over
50 ms came in bursts every 2-3 s, 400-600 frames each. Each client
walks the paper office there and back (about 80 s at 10 Hz), starting at
its own point but never running off the end, so a session is not kidnapped by a jump
back to the start: after the first second or so every session is a converged walk.

    python benchmarks/load.py --sessions 20 --rate 10 --seconds 60 --particles 10000
    python benchmarks/load.py --sessions 120 --seconds 30 --store redis://127.0.0.1:6379/0
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import os
import socket
import statistics
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import httpx
import numpy as np
import websockets

from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.server import SERVING_GC_THRESHOLDS
from app.simulation.scenarios import PAPER_PATH, paper_config
from app.simulation.simulator import simulate


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux /proc), seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_until_healthy(port: int, proc: subprocess.Popen[bytes], timeout_s: float = 120) -> str:
    """host:port of a server started on ``port`` once /healthz answers (killed if never)."""
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                return f"127.0.0.1:{port}"
        except httpx.HTTPError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("the server did not start")


def start_server(max_particles: int, store: str) -> tuple[str, subprocess.Popen[bytes]]:
    """`bearings serve` in its own process, as in production (the client gets its own GIL)."""
    port = free_port()
    env = {**os.environ, "BEARINGS_MAX_PARTICLES": str(max(max_particles, 100_000))}
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--no-viser",
         "--log-level", "warning", "--max-sessions", "1000", "--store", store],
        env=env,
    )  # fmt: skip
    return wait_until_healthy(port, proc), proc


async def one_session(
    url: str,
    frames: list[dict],
    rate: float,
    seconds: float,
    particles: int,
    seed: int,
    stagger: float = 0.0,
    answered_at: list[float] | None = None,
) -> tuple[list[tuple[float, float]], int]:
    """One client; ``answered_at`` collects when each answer came (``perf_counter``)."""
    # Phones start their sessions at their own moments, within ``stagger`` seconds.
    await asyncio.sleep(stagger * np.random.default_rng(seed + 1_000_003).random())
    async with httpx.AsyncClient(base_url=f"http://{url}", timeout=30) as http:
        body = {"map": "paper_office", "particles": particles, "seed": seed}
        r = await http.post("/sessions", json=body)
        # A busy worker says 503 and when to come back; an app comes back, for a minute
        # (ten tries were not enough while 120 sessions localized from nothing at once:
        # the sessions given up on left the steady load short of what was asked).
        patience = time.perf_counter() + 60.0
        while r.status_code == 503 and time.perf_counter() < patience:
            await asyncio.sleep(float(r.headers.get("retry-after", 1.0)))
            r = await http.post("/sessions", json=body)
        r.raise_for_status()
        sid = r.json()["id"]
    latencies: list[tuple[float, float]] = []  # (seconds since start, latency)
    errors = 0
    period = 1.0 / rate
    room = max(1, len(frames) - int(seconds * rate) - 1)
    first = (seed * 7) % room  # its own stretch of the walk, never past the end
    async with websockets.connect(f"ws://{url}/sessions/{sid}/stream", max_size=2**22) as ws:
        # Phones are not synchronized: each client starts at its own point of the period
        # (else every client sends in the same instant and the last waits for all others).
        await asyncio.sleep(period * np.random.default_rng(seed).random())
        start = time.perf_counter()
        i = 0
        while time.perf_counter() - start < seconds:
            frame = frames[(first + i) % len(frames)]
            t0 = time.perf_counter()
            await ws.send(json.dumps(frame))
            reply = json.loads(await ws.recv())
            now = time.perf_counter()
            latencies.append((t0 - start, now - t0))
            if answered_at is not None:
                answered_at.append(now)
            if "error" in reply:
                errors += 1
            i += 1
            await asyncio.sleep(max(0.0, start + i * period - time.perf_counter()))
    async with httpx.AsyncClient(base_url=f"http://{url}") as http:
        await http.delete(f"/sessions/{sid}")
    return latencies, errors


async def cpu_at(pid: int, when: float) -> float:
    """The server's CPU seconds at ``perf_counter`` time ``when``."""
    await asyncio.sleep(max(0.0, when - time.perf_counter()))
    return cpu_seconds(pid)


def paper_walk_frames(phone_rate_hz: float | None = None) -> list[dict]:
    """The clients' frames: the paper office walked there and back, as JSON-ready data.

    By default the paper's walk (a frame every 0.2 s of walking, no timestamps), which
    the clients send at their rate (at 10 Hz, a walk at twice the speed). With
    ``phone_rate_hz``, as a phone sends it: a frame every 1 / rate s of the walk at its
    own speed, each with its ``timestamp`` (the walk's time)."""
    office = load_map(bundled_maps_dir() / "paper_office.json")
    there_and_back = PAPER_PATH + PAPER_PATH[-2::-1] + PAPER_PATH[1:]
    config = replace(paper_config("nominal", 360), path=there_and_back)
    if phone_rate_hz is not None:
        config = replace(config, rate_hz=phone_rate_hz)
    frames = simulate(office, config, np.random.default_rng(0))
    out = [f.to_contract() for f in frames]
    if phone_rate_hz is not None:
        for f, d in zip(frames, out, strict=True):
            d["timestamp"] = round(f.t, 4)
    return out


def quiet_collector() -> None:
    """Keep the generator's garbage collection out of the latencies it measures.

    Everything made so far (the imported libraries, the frames) is frozen out of the
    collector's reach, and the youngest generation is collected as rarely as the
    server's (:data:`app.server.SERVING_GC_THRESHOLDS`). Without this, the generator
    itself stopped for full collections of up to 0.12 s in a 30 s run at 120 sessions
    (walking its imports and the latencies it had gathered) and for 36 collections of
    the middle generation of up to 14 ms: answers that arrived meanwhile were counted
    late, and the frames it should have sent meanwhile went out in one burst.
    """
    gc.collect()
    gc.freeze()
    gc.set_threshold(*SERVING_GC_THRESHOLDS)


async def run(args: argparse.Namespace, url: str, pid: int | None = None) -> dict[str, object]:
    frames = paper_walk_frames(args.rate if args.phone else None)
    quiet_collector()
    t0, cpu0 = time.perf_counter(), time.process_time()
    window = (t0 + args.stagger + args.warmup, t0 + args.seconds)
    answered_at: list[float] = []
    marks = []
    if pid is not None and window[1] - window[0] >= 1.0:
        marks = [asyncio.ensure_future(cpu_at(pid, w)) for w in window]
    results = await asyncio.gather(
        *(
            one_session(
                url, frames, args.rate, args.seconds, args.particles, s, args.stagger, answered_at
            )
            for s in range(args.sessions)
        ),
        return_exceptions=True,
    )
    wall, client_cpu = time.perf_counter() - t0, time.process_time() - cpu0
    steady_cpu = None
    if marks:
        begin, end = await asyncio.gather(*marks)
        answered = sum(1 for t in answered_at if window[0] <= t < window[1])
        steady_cpu = round(1000 * (end - begin) / max(answered, 1), 3)
    pairs = [x for r in results if not isinstance(r, BaseException) for x in r[0]]
    lat = [latency for _, latency in pairs]
    steady = sorted(1e3 * latency for t, latency in pairs if t >= args.warmup)
    errors = sum(r[1] for r in results if not isinstance(r, BaseException))
    failed = sum(1 for r in results if isinstance(r, BaseException))
    lat_ms = sorted(1e3 * x for x in lat)
    q = statistics.quantiles(lat_ms, n=100) if len(lat_ms) >= 2 else [float("nan")] * 99
    return {
        "sessions": args.sessions,
        "rate_hz": args.rate,
        "phone": args.phone,
        "seconds": args.seconds,
        "particles": args.particles,
        "frames": len(lat_ms),
        "frames_per_s": round(len(lat_ms) / wall, 1),
        "steady_frames_per_s": round(len(steady) / max(args.seconds - args.warmup, 1e-9), 1),
        "client_cpu_share": round(client_cpu / wall, 2),
        "target_frames_per_s": args.sessions * args.rate,
        "p50_ms": round(q[49], 1),
        "p95_ms": round(q[94], 1),
        "max_ms": round(lat_ms[-1], 1) if lat_ms else None,
        "steady_after_s": args.warmup,
        "stagger_s": args.stagger,
        "steady_p50_ms": round(statistics.median(steady), 1) if steady else None,
        "steady_p95_ms": round(statistics.quantiles(steady, n=100)[94], 1)
        if len(steady) > 1
        else None,
        "errors": errors,
        "failed_sessions": failed,
        **({"steady_server_cpu_s_per_1000_frames": steady_cpu} if steady_cpu is not None else {}),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--sessions", type=int, default=20)
    parser.add_argument("--rate", type=float, default=10.0, help="frames per second per session")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--particles", type=int, default=10_000)
    parser.add_argument("--url", help="host:port of a running server or proxy (default: start one)")
    parser.add_argument(
        "--store", default="memory", help="--store of the server started (default memory)"
    )
    parser.add_argument(
        "--stagger", type=float, default=0.0,
        help="sessions start at random moments within this many seconds (default 0: all "
        "at once, so their filters' periodic searches fall on the same frames)",
    )  # fmt: skip
    parser.add_argument(
        "--phone", action="store_true",
        help="frames as a phone sends them: the walk at its own speed, a frame every "
        "1 / --rate s with its timestamp (default: the paper's 5 Hz walk sent at --rate, "
        "no timestamps)",
    )  # fmt: skip
    parser.add_argument(
        "--warmup", type=float, default=10.0,
        help="seconds after which latencies also count as steady state (all sessions start lost)",
    )  # fmt: skip
    args = parser.parse_args()
    proc = None
    url = args.url
    if url is None:
        url, proc = start_server(args.particles, args.store)
    try:
        cpu0 = cpu_seconds(proc.pid) if proc is not None else None
        report = asyncio.run(run(args, url, None if proc is None else proc.pid))
        if proc is not None and cpu0 is not None:
            cpu = cpu_seconds(proc.pid) - cpu0
            report["store"] = args.store
            report["server_cpu_s"] = round(cpu, 1)
            report["server_cpu_s_per_1000_frames"] = round(1000 * cpu / max(report["frames"], 1), 3)  # type: ignore[call-overload]
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=30)
    print(json.dumps(report))
    r = report
    print(
        f"{r['sessions']} sessions x {r['rate_hz']} Hz x {r['particles']} particles, "
        f"{r['seconds']} s: {r['frames_per_s']} frames/s (target {r['target_frames_per_s']}), "
        f"p50 {r['p50_ms']} ms, p95 {r['p95_ms']} ms (after {r['steady_after_s']} s: "
        f"{r['steady_frames_per_s']} frames/s, p50 {r['steady_p50_ms']} ms, "
        f"p95 {r['steady_p95_ms']} ms), errors {r['errors']}, "
        f"failed sessions {r['failed_sessions']}, generator CPU {r['client_cpu_share']}"
        + (
            f"; server CPU {r['server_cpu_s_per_1000_frames']} s per 1,000 frames"
            if "server_cpu_s_per_1000_frames" in r
            else ""
        )
        + (
            f" ({r['steady_server_cpu_s_per_1000_frames']} s steady)"
            if "steady_server_cpu_s_per_1000_frames" in r
            else ""
        )
    )


if __name__ == "__main__":
    main()
