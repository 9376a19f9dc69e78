"""A real uvicorn server on a free port, real WebSocket clients, many sessions at once."""

from __future__ import annotations

import asyncio
import gc
import json
import time
from collections.abc import Iterator

import httpx
import numpy as np
import pytest
import websockets

from app.main import create_app
from app.server import SERVING_GC_THRESHOLDS
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate
from tests.helpers import free_port, make_settings, paper_office, serving


@pytest.fixture(scope="module")
def server_url() -> Iterator[str]:
    port = free_port()
    with serving(create_app(make_settings(max_sessions=50, port=port)), port) as url:
        yield url


FRAMES = [
    f.to_contract()
    for f in simulate(
        paper_office(),
        paper_config("nominal", 360),
        np.random.default_rng(11),
    )[:30]
]


async def stream_session(
    url: str, n_frames: int, seed: int, particles: int = 500
) -> tuple[str, list[int], dict]:
    async with httpx.AsyncClient(base_url=f"http://{url}") as http:
        r = await http.post(
            "/sessions", json={"map": "paper_office", "particles": particles, "seed": seed}
        )
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
    seqs = []
    last: dict = {}
    async with websockets.connect(f"ws://{url}/sessions/{sid}/stream") as ws:
        # One frame at a time, as a phone at a steady rate would: nothing is merged.
        for frame in FRAMES[:n_frames]:
            await ws.send(json.dumps(frame))
            last = json.loads(await ws.recv())
            seqs.append(last["seq"])
    return sid, seqs, last


def test_stream_over_a_real_server(server_url: str) -> None:
    sid, seqs, last = asyncio.run(stream_session(server_url, 30, 1, particles=4000))
    assert seqs == list(range(1, 31))
    assert last["converged"]
    truth = FRAMES[29]["truth"]
    assert np.hypot(last["pose"]["x"] - truth["x"], last["pose"]["y"] - truth["y"]) < 0.25
    got = httpx.get(f"http://{server_url}/sessions/{sid}").json()
    assert got["frames"] == 30


def test_twenty_sessions_at_once_each_in_order(server_url: str) -> None:
    async def main() -> list[tuple[str, list[int], dict]]:
        return await asyncio.gather(*(stream_session(server_url, 15, s) for s in range(20)))

    results = asyncio.run(main())
    assert len({sid for sid, _, _ in results}) == 20
    for _, seqs, _ in results:
        assert seqs == list(range(1, 16))


def test_health_stays_responsive_while_streaming(server_url: str) -> None:
    async def main() -> float:
        task = asyncio.gather(*(stream_session(server_url, 30, s) for s in range(6)))
        worst = 0.0
        async with httpx.AsyncClient(base_url=f"http://{server_url}") as http:
            for _ in range(10):
                t0 = time.perf_counter()
                assert (await http.get("/healthz")).status_code == 200
                worst = max(worst, time.perf_counter() - t0)
                await asyncio.sleep(0.05)
        await task
        return worst

    # Generous bound: the event loop is never blocked by filter work.
    assert asyncio.run(main()) < 1.0


def test_unknown_session_close_reason_over_the_wire(server_url: str) -> None:
    async def main() -> websockets.exceptions.ConnectionClosed:
        async with websockets.connect(f"ws://{server_url}/sessions/missing/stream") as ws:
            try:
                await ws.recv()
            except websockets.exceptions.ConnectionClosed as exc:
                return exc
        raise AssertionError("the server did not close the connection")

    exc = asyncio.run(main())
    assert exc.rcvd is not None and exc.rcvd.code == 1008
    assert "no session" in exc.rcvd.reason


def test_start_up_is_frozen_then_collection_resumes() -> None:
    """`bearings serve` starts with the garbage collector off (app/cli.py); once the
    service has started, what start-up made is frozen and collection is back on, with
    the serving thresholds."""
    port = free_port()
    app = create_app(make_settings(port=port))
    thresholds = gc.get_threshold()
    gc.disable()
    try:
        with serving(app, port, freeze_start_up=True) as url:
            assert gc.isenabled()
            assert gc.get_freeze_count() > 0
            assert gc.get_threshold() == SERVING_GC_THRESHOLDS
            r = httpx.post(f"http://{url}/sessions", json={"map": "paper_office"})
            assert r.status_code == 201
    finally:
        gc.unfreeze()
        gc.set_threshold(*thresholds)
        gc.enable()
