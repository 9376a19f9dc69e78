"""The live view is private: an anonymous viewer sees only what was shared, never an id.

A real viser server (the view's own) and a raw WebSocket client speaking viser's
protocol, reading every byte the server sends it.
"""

from __future__ import annotations

import asyncio
import functools
import time

import msgspec
import pytest
import viser
import websockets
import zstandard
from viser._messages import ViewerCameraMessage

from app.config import Settings
from app.demo import new_walk
from app.main import create_app
from app.service.types import FrameInput, SessionSpec
from app.viz.view import LiveView
from tests.helpers import free_port, make_manager


def decode(message: bytes) -> bytes:
    """The msgpack payload of one viser message (header, zstd-compressed payload, buffers)."""
    size = int.from_bytes(message[:8], "little")
    compressed = int.from_bytes(message[8:16], "little")
    return zstandard.ZstdDecompressor().decompress(message[16 : 16 + compressed], size)


async def watch_as_anonymous(port: int, seconds: float) -> bytes:
    """Everything an anonymous browser on the view's port is sent during ``seconds``."""
    seen = b""
    async with websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], max_size=2**26
    ) as ws:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            try:
                message = await asyncio.wait_for(ws.recv(), left)
            except TimeoutError:
                break
            if isinstance(message, bytes):
                seen += decode(message) + message[16:]
    return seen


def test_an_anonymous_viewer_sees_only_shared_sessions_and_no_id() -> None:
    async def main() -> None:
        manager = make_manager()
        view = LiveView(manager, port=free_port(), start_walk=functools.partial(new_walk, manager))
        view.start()
        try:
            private = await manager.create(SessionSpec(map_name="paper_office", particles=500))
            shared = await manager.create(
                SessionSpec(map_name="paper_office", particles=500, share_view=True)
            )
            for s in (private, shared):
                await manager.process(s.id, FrameInput())
            await asyncio.sleep(0.3)  # a redraw cycle
            seen = await watch_as_anonymous(view.port, 1.5)
            assert view.controls is not None
            label = view.controls.label(shared)
            assert label.encode() in seen  # the shared session is listed, by its label
            for secret in (private.id, shared.id, private.tag):
                assert secret.encode() not in seen
            assert set(view.controls.session.options) == {"(none)", label}
            assert view.watched == shared.id
            view.watch(private.id)  # even if asked, the view does not draw a private session
            assert view.refresh() is False and view.watched is None
        finally:
            view.stop()

    asyncio.run(main())


CAMERA = msgspec.msgpack.encode(
    ViewerCameraMessage(
        wxyz=(1.0, 0.0, 0.0, 0.0),
        position=(0.0, 0.0, 10.0),
        fov=1.0,
        near=0.01,
        far=100.0,
        image_height=480,
        image_width=640,
        look_at=(0.0, 0.0, 0.0),
        up_direction=(0.0, 0.0, 1.0),
    ).as_serializable_dict([])
)


async def drain(ws: websockets.ClientConnection) -> None:
    async for _ in ws:
        pass


def test_view_walks_end_with_their_viewer_and_after_the_time_limit() -> None:
    async def main() -> None:
        manager = make_manager()
        view = LiveView(manager, port=free_port(), start_walk=functools.partial(new_walk, manager))
        view.start()
        assert view.server is not None and view.controls is not None
        try:
            async with websockets.connect(
                f"ws://127.0.0.1:{view.port}", subprotocols=[f"viser-v{viser.__version__}"]
            ) as ws:
                await ws.send(CAMERA)  # viser counts a client once it reports its camera
                reading = asyncio.create_task(drain(ws))
                deadline = time.monotonic() + 5
                while not view.server.get_clients() and time.monotonic() < deadline:
                    await asyncio.sleep(0.05)
                (viewer,) = view.server.get_clients()
                sid = await view.controls.start_walk(viewer)
                deadline = time.monotonic() + 10  # the walk simulates its path first
                while manager.get(sid).frames < 1 and time.monotonic() < deadline:
                    await asyncio.sleep(0.05)
                assert manager.get(sid).frames >= 1 and manager.get(sid).shared is False
                assert view.controls.label(manager.get(sid)) == "walk 1 (paper_office)"
                reading.cancel()
            deadline = time.monotonic() + 5  # the viewer left: its walk ends
            while any(s.id == sid for s in manager.sessions()) and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            assert all(s.id != sid for s in manager.sessions())

            manager.settings = manager.settings.model_copy(update={"demo_walk_max_s": 0.5})
            sid = await view.controls.start_walk(None)
            deadline = time.monotonic() + 5
            while any(s.id == sid for s in manager.sessions()) and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            assert all(s.id != sid for s in manager.sessions())
        finally:
            view.stop()

    asyncio.run(main())


@pytest.mark.parametrize("host", ["0.0.0.0", "192.0.2.7"])
def test_the_view_listens_on_loopback_whatever_the_api_host(host: str) -> None:
    from fastapi.testclient import TestClient

    settings = Settings(host=host, insecure_open=True, viser_port=free_port(), max_sessions=2)
    with TestClient(create_app(settings)) as client:
        view = client.app.state.view  # type: ignore[attr-defined]
        assert view is not None and view.host == "127.0.0.1"
