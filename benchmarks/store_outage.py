"""Store outage: Redis killed under load and restarted empty, then the worker killed.

Starts a private redis-server (in memory only, no persistence) and two workers
(``bearings serve --store redis://...``) on loopback; N people stream the paper-office
walk at R Hz over WebSocket to the first worker. After ``--warmup`` seconds (every
session converged and steady), Redis is killed with SIGKILL, left down for ``--outage``
seconds, and started again empty on the same port. Then, ``--settle`` seconds later,
the first worker is killed with SIGKILL; each client reconnects to the second worker
and goes on, as a phone would after its connection dropped.

It reports:

* error answers (every answer that is an ``{"error": ...}``), in each phase;
* the answers' latency (send to answer) before the outage, during it, in the two
  seconds after Redis came back, and after the fail-over; and how many answers carried
  ``state_not_persisted``;
* how long after Redis came back every session was stored again: polled from Redis
  every 20 ms, a session counts once Redis holds a frame of it at least as late as the
  last one its client had been answered when Redis started (the checkpoint's or the
  journal's); and the worker's own figure (``bearings_store_recovery_seconds``);
* how many people the first worker had admitted when Redis was killed: a worker whose
  core is saturated answers new sessions 503 ``busy`` (come back later), and a person
  still waiting when that worker is killed never had a session; they are counted as
  ``never_admitted``, apart from ``failed_clients`` (people with a session whose stream
  failed), and the storage figures are over the admitted sessions;
* the fail-over: for each session, the seconds from its connection dropping to its
  next answer, and whether it went on where it was: the second worker's ``frames`` for
  it is the number its client had been answered, or one more (a frame sent but whose
  answer was lost with the connection), and the next answer's ``seq`` follows.

    python -m benchmarks.store_outage --sessions 120 --rate 10 --outage 5
    python -m benchmarks.store_outage --sessions 120 --rate 10 --outage 0  # fail-over only

Load goes to 127.0.0.1 only; the run lasts ``--warmup + --outage + --settle +
--after`` seconds (plus start-up), and every process it started is stopped at the end.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import signal
import statistics
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import httpx
import numpy as np
import redis
import websockets

from benchmarks.load import free_port, paper_walk_frames, quiet_collector, start_server

NOT_PERSISTED = "state_not_persisted"


class Redis:
    """redis-server on a fixed port without persistence, killable and restartable."""

    def __init__(self, data_dir: Path) -> None:
        binary = shutil.which("redis-server")
        if binary is None:
            raise SystemExit("redis-server is not installed")
        self.binary = binary
        self.port = free_port()
        self.data_dir = data_dir
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        self.proc = subprocess.Popen(
            [self.binary, "--port", str(self.port), "--bind", "127.0.0.1", "--save", "",
             "--appendonly", "no", "--dir", str(self.data_dir)],
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
        client = redis.Redis(port=self.port)
        deadline = time.monotonic() + 20
        while True:
            try:
                client.ping()
                return
            except redis.ConnectionError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)

    def kill(self) -> None:
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)


@dataclass
class Answer:
    at: float  # perf_counter when the answer came
    latency_s: float
    seq: int | None
    error: str | None
    not_persisted: bool


@dataclass
class Person:
    """One client: streams the walk to the first worker, then to the second."""

    seed: int
    sid: str = ""
    answers: list[Answer] = field(default_factory=list)
    answered: int = 0  # frames answered (the session's frame count, as the client knows it)
    #: After the fail-over: (seconds from the drop to the next answer, where it was).
    resumed: tuple[float, bool] | None = None
    stop: bool = False


async def stream(
    person: Person,
    workers: list[str],
    frames: list[dict],
    args: argparse.Namespace,
) -> None:
    # People start at their own moments within ``--stagger`` seconds (load.py says why).
    await asyncio.sleep(args.stagger * np.random.default_rng(person.seed + 1_000_003).random())
    async with httpx.AsyncClient(base_url=f"http://{workers[0]}", timeout=30) as http:
        body = {"map": "paper_office", "particles": args.particles, "seed": person.seed}
        r = await http.post("/sessions", json=body)
        patience = time.perf_counter() + 60.0
        while r.status_code == 503 and time.perf_counter() < patience:  # busy: come back
            await asyncio.sleep(float(r.headers.get("retry-after", 1.0)))
            r = await http.post("/sessions", json=body)
        r.raise_for_status()
        person.sid = r.json()["id"]
    period = 1.0 / args.rate
    first = (person.seed * 7) % max(1, len(frames) // 3)
    i = 0  # next frame of the walk to send
    await asyncio.sleep(period * np.random.default_rng(person.seed).random())
    dropped_at: float | None = None
    for url in workers:
        try:
            async with websockets.connect(
                f"ws://{url}/sessions/{person.sid}/stream", max_size=2**22, open_timeout=10
            ) as ws:
                check = None
                if dropped_at is not None:
                    async with httpx.AsyncClient(base_url=f"http://{url}", timeout=30) as http:
                        r = await http.get(f"/sessions/{person.sid}")
                        r.raise_for_status()
                        frames_there = r.json()["frames"]
                    if frames_there == person.answered + 1:
                        i += 1  # the unanswered frame was processed; its answer was lost
                    check = frames_there in (person.answered, person.answered + 1)
                    person.answered = frames_there
                start = time.perf_counter()
                sent = 0
                while not person.stop:
                    frame = frames[(first + i) % len(frames)]
                    t0 = time.perf_counter()
                    await ws.send(json.dumps(frame))
                    reply = json.loads(await ws.recv())
                    now = time.perf_counter()
                    error = reply["error"]["code"] if "error" in reply else None
                    seq = reply.get("seq")
                    person.answers.append(
                        Answer(
                            now,
                            now - t0,
                            seq,
                            error,
                            any(w.startswith(NOT_PERSISTED) for w in reply.get("warnings", [])),
                        )
                    )
                    if check is not None and dropped_at is not None:
                        person.resumed = (now - dropped_at, check and seq == person.answered + 1)
                        dropped_at = None
                    if error is None:
                        person.answered = seq
                        i += 1
                    sent += 1
                    await asyncio.sleep(max(0.0, start + sent * period - time.perf_counter()))
                return
        except (OSError, websockets.WebSocketException):
            dropped_at = time.perf_counter()
    raise RuntimeError(f"session {person.seed}: both workers failed")


def stored_frames(client: redis.Redis, sid: str) -> int:
    base = f"bearings:{{{sid}}}"
    last = int(cast(bytes | None, client.get(f"{base}:ckpt:frames")) or -1)
    tail = cast(bytes | None, client.lindex(f"{base}:journal", -1))
    return max(last, -1 if tail is None else int(tail.partition(b"|")[0]))


def quantiles_ms(answers: list[Answer]) -> dict[str, float | int | None]:
    ms = sorted(1e3 * a.latency_s for a in answers)
    if len(ms) < 2:
        return {"answers": len(ms), "p50_ms": None, "p95_ms": None, "max_ms": None}
    q = statistics.quantiles(ms, n=100)
    return {
        "answers": len(ms),
        "p50_ms": round(q[49], 1),
        "p95_ms": round(q[94], 1),
        "max_ms": round(ms[-1], 1),
        "errors": sum(a.error is not None for a in answers),
        "not_persisted": sum(a.not_persisted for a in answers),
    }


def recovery_metric(worker: str) -> float | None:
    text = httpx.get(f"http://{worker}/metrics", timeout=5).text
    for line in text.splitlines():
        if line.startswith("bearings_store_recovery_seconds "):
            return float(line.split()[1])
    return None


async def run(args: argparse.Namespace, store: Redis, workers: list[str]) -> dict[str, object]:
    frames = paper_walk_frames()
    quiet_collector()
    people = [Person(seed) for seed in range(args.sessions)]
    tasks = [asyncio.create_task(stream(p, workers, frames, args)) for p in people]
    await asyncio.sleep(args.warmup)
    t_kill = time.perf_counter()
    admitted = sum(bool(p.sid) for p in people)
    health = None
    if args.outage > 0:  # (0: no outage, the fail-over alone, to compare)
        store.kill()
        async with httpx.AsyncClient(timeout=5) as http:
            await asyncio.sleep(min(1.0, args.outage / 2))
            health = (await http.get(f"http://{workers[0]}/healthz")).json()
        await asyncio.sleep(max(0.0, t_kill + args.outage - time.perf_counter()))
        await asyncio.to_thread(store.start)
    t_back = time.perf_counter()
    due = {p.sid: p.answered for p in people if p.sid}
    client = redis.Redis(port=store.port)
    stored_again_s = None
    while time.perf_counter() - t_back < args.settle:
        if all(stored_frames(client, sid) >= n for sid, n in due.items()):
            stored_again_s = time.perf_counter() - t_back
            break
        await asyncio.sleep(0.02)
    await asyncio.sleep(max(0.0, t_back + args.settle - time.perf_counter()))
    worker_recovery_s = recovery_metric(workers[0])
    t_failover = time.perf_counter()
    args.first_worker.send_signal(signal.SIGKILL)
    args.first_worker.wait(timeout=10)
    await asyncio.sleep(args.after)
    for p in people:
        p.stop = True
    results = await asyncio.gather(*tasks, return_exceptions=True)
    answers = [a for p in people for a in p.answers]
    phases = {
        "before": [a for a in answers if a.at < t_kill and a.at >= t_kill - 10],
        "outage": [a for a in answers if t_kill <= a.at < t_back],
        "first_2s_back": [a for a in answers if t_back <= a.at < t_back + 2],
        "after_failover": [a for a in answers if a.at >= t_failover],
    }
    resumed = [p.resumed for p in people if p.resumed is not None]
    waits = sorted(w for w, _ in resumed)
    return {
        "sessions": args.sessions,
        "rate_hz": args.rate,
        "particles": args.particles,
        "outage_s": args.outage,
        "walk_frames": len(frames),
        "error_answers": sum(a.error is not None for a in answers),
        "admitted_before_outage": admitted,
        "never_admitted": sum(not p.sid for p in people),
        "failed_clients": sum(
            isinstance(r, BaseException) and bool(p.sid)
            for p, r in zip(people, results, strict=True)
        ),
        "healthz_during_outage": health,
        "phases": {name: quantiles_ms(got) for name, got in phases.items()},
        "stored_again_s": None if stored_again_s is None else round(stored_again_s, 3),
        "worker_recovery_s": worker_recovery_s,
        "failover": {
            "resumed": len(resumed),
            "where_it_was": sum(ok for _, ok in resumed),
            "wait_median_s": round(statistics.median(waits), 2) if waits else None,
            "wait_max_s": round(waits[-1], 2) if waits else None,
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--sessions", type=int, default=120)
    parser.add_argument("--rate", type=float, default=10.0, help="frames per second per person")
    parser.add_argument("--particles", type=int, default=10_000)
    parser.add_argument(
        "--stagger", type=float, default=5.0, help="people start within this many seconds"
    )
    parser.add_argument("--warmup", type=float, default=25.0, help="seconds before Redis dies")
    parser.add_argument(
        "--outage", type=float, default=5.0, help="seconds Redis stays down (0: not killed)"
    )
    parser.add_argument(
        "--settle", type=float, default=5.0, help="seconds from Redis's restart to the kill"
    )
    parser.add_argument("--after", type=float, default=10.0, help="seconds after the kill")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        store = Redis(Path(tmp))
        store.start()
        procs: list[subprocess.Popen[bytes]] = []
        try:
            workers = []
            for _ in range(2):
                url, proc = start_server(args.particles, store.url)
                workers.append(url)
                procs.append(proc)
            args.first_worker = procs[0]
            report = asyncio.run(run(args, store, workers))
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.terminate()
                    proc.wait(timeout=30)
            store.stop()
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
