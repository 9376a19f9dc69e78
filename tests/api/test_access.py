"""Keys, ownership, quotas and origins over a real uvicorn server with real clients.

The tests share one server, so none may depend on what another left behind: every
session a test creates is deleted after it (passed or not, :func:`new_session`), and
each rate-limited key serves one test only (a key's token bucket outlives its sessions).
"""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest
import websockets
from websockets.exceptions import InvalidStatus

from app.main import create_app
from tests.helpers import free_port, make_settings, serving

ALICE = "alice-key-0123456789abcdef"
BOB = "bob-key-0123456789abcdef-bob"
SLOW = "slow-key-0123456789abcdef"
SLOW_WS = "slow-websocket-key-0123456789"
KEYS = f"""# name key max_sessions max_particles max_frames_per_s
alice   {ALICE}   2 3000 1000
bob     {BOB}     3 -    -
slow    {SLOW}    1 1000 2
slow-ws {SLOW_WS} 1 1000 2
"""


def auth(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    keys = tmp_path_factory.mktemp("keys") / "keys.txt"
    keys.write_text(KEYS)
    port = free_port()
    settings = make_settings(
        api_keys_file=keys, port=port, allowed_origins="https://app.example.org"
    )
    with serving(create_app(settings), port) as served:
        yield served


@pytest.fixture
def http(url: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=f"http://{url}") as client:
        yield client


NewSession = Callable[..., str]


@pytest.fixture
def new_session(http: httpx.Client) -> Iterator[NewSession]:
    """``new_session(key, particles=500)``: a session of ``key`` on the paper office,
    deleted after the test (whatever the test did), so that no test finds a quota
    another one used up."""
    made: list[tuple[str, str]] = []

    def make(key: str, particles: int = 500) -> str:
        r = http.post(
            "/sessions", json={"map": "paper_office", "particles": particles}, headers=auth(key)
        )
        assert r.status_code == 201, r.text
        made.append((r.json()["id"], key))
        return made[-1][0]

    yield make
    for sid, key in made:
        assert http.delete(f"/sessions/{sid}", headers=auth(key)).status_code in (204, 404)


def test_every_route_but_healthz_needs_a_key(http: httpx.Client) -> None:
    assert http.get("/healthz").status_code == 200
    for method, path in [
        ("GET", "/maps"),
        ("GET", "/metrics"),
        ("GET", "/"),
        ("GET", "/docs"),
        ("POST", "/sessions"),
        ("GET", "/sessions/anything"),
    ]:
        r = http.request(method, path)
        assert r.status_code == 401, (method, path)
        assert "Authorization: Bearer" in r.json()["message"]
        assert r.headers["www-authenticate"].startswith("Bearer")
    r = http.get("/maps", headers=auth("not-a-key-but-long-enough"))
    assert r.status_code == 401 and "not valid" in r.json()["message"]
    assert http.get("/maps", headers=auth(ALICE)).status_code == 200


def _same_text(message: str) -> str:
    """The message with the server's uptime ("started 58 s ago") made constant."""
    return re.sub(r"started \d+ s ago", "started N s ago", message)


def test_another_key_cannot_read_delete_or_stream_into_a_session(
    http: httpx.Client, url: str, new_session: NewSession
) -> None:
    sid = new_session(ALICE)
    missing = http.get("/sessions/never-existed-at-all", headers=auth(BOB))
    for r in (
        http.get(f"/sessions/{sid}", headers=auth(BOB)),
        http.post(f"/sessions/{sid}/frames", json={}, headers=auth(BOB)),
        http.delete(f"/sessions/{sid}", headers=auth(BOB)),
    ):
        assert r.status_code == 404
        # Exactly like a session that does not exist: only the id and the server's uptime
        # (which ticks between the two requests) differ.
        assert _same_text(r.json()["message"].replace(sid, "X")) == _same_text(
            missing.json()["message"].replace("never-existed-at-all", "X")
        )

    async def stream_as(key: str) -> int | None:
        try:
            async with websockets.connect(
                f"ws://{url}/sessions/{sid}/stream", additional_headers=auth(key)
            ) as ws:
                await ws.send("{}")
                return json.loads(await ws.recv())["seq"]
        except websockets.ConnectionClosed as exc:
            assert exc.rcvd is not None and exc.rcvd.code == 1008
            assert "no session" in exc.rcvd.reason
            return None

    assert asyncio.run(stream_as(BOB)) is None
    got = http.get(f"/sessions/{sid}", headers=auth(ALICE)).json()
    assert got["frames"] == 0  # nothing of bob's reached it
    assert asyncio.run(stream_as(ALICE)) == 1
    assert http.delete(f"/sessions/{sid}", headers=auth(ALICE)).status_code == 204


def test_websocket_key_in_header_or_query_and_refused_without(
    url: str, http: httpx.Client, new_session: NewSession
) -> None:
    sid = new_session(BOB)

    async def main() -> None:
        async with websockets.connect(f"ws://{url}/sessions/{sid}/stream?key={BOB}") as ws:
            await ws.send("{}")
            assert json.loads(await ws.recv())["seq"] == 1
        with pytest.raises(InvalidStatus) as info:
            async with websockets.connect(f"ws://{url}/sessions/{sid}/stream"):
                pass
        assert info.value.response.status_code == 401
        assert b"API key" in info.value.response.body

    asyncio.run(main())


def test_quotas_answer_429_with_retry_after(http: httpx.Client, new_session: NewSession) -> None:
    first = new_session(ALICE, 1000)
    second = new_session(ALICE, 1000)
    r = http.post("/sessions", json={"map": "paper_office", "particles": 500}, headers=auth(ALICE))
    assert r.status_code == 429 and int(r.headers["retry-after"]) >= 1
    assert "quota of 2 sessions" in r.json()["message"] and r.json()["code"] == "session_quota"
    http.delete(f"/sessions/{second}", headers=auth(ALICE))
    r = http.post("/sessions", json={"map": "paper_office", "particles": 2500}, headers=auth(ALICE))
    assert r.status_code == 429 and int(r.headers["retry-after"]) >= 1
    assert r.json()["code"] == "particle_quota" and "1000 of its 3000" in r.json()["message"]
    r = http.post("/sessions", json={"map": "paper_office", "particles": 5000}, headers=auth(ALICE))
    assert r.status_code == 422 and "quota of 3000 particles" in r.json()["message"]
    http.delete(f"/sessions/{first}", headers=auth(ALICE))

    sid = new_session(SLOW, 200)  # two frames a second, one second of burst
    codes = [
        http.post(f"/sessions/{sid}/frames", json={}, headers=auth(SLOW)).status_code
        for _ in range(4)
    ]
    assert codes[:2] == [200, 200] and 429 in codes[2:]
    r = http.post(f"/sessions/{sid}/frames", json={}, headers=auth(SLOW))
    assert r.status_code == 429 and r.headers["retry-after"] == "1"
    assert r.json()["code"] == "rate_limited" and "2 frames per second" in r.json()["message"]


def test_rate_quota_over_websocket_is_an_error_message_and_the_stream_stays(
    url: str, new_session: NewSession
) -> None:
    sid = new_session(SLOW_WS, 200)  # a key of its own: its bucket is full

    async def main() -> list[dict]:
        async with websockets.connect(f"ws://{url}/sessions/{sid}/stream?key={SLOW_WS}") as ws:
            for _ in range(4):
                await ws.send("{}")
            return [json.loads(await ws.recv()) for _ in range(4)]

    replies = asyncio.run(main())
    errors = [r["error"] for r in replies if "error" in r]
    assert errors and all(e["code"] == "rate_limited" and e["retry_after_s"] > 0 for e in errors)
    assert any("seq" in r for r in replies)


@pytest.mark.parametrize(
    ("origin", "allowed"),
    [
        (None, True),  # not a browser
        ("https://app.example.org", True),  # BEARINGS_ALLOWED_ORIGINS
        ("SAME", True),  # the service's own page
        ("https://evil.example.com", False),
        ("null", False),
    ],
)
def test_websocket_origins(
    url: str, new_session: NewSession, origin: str | None, allowed: bool
) -> None:
    sid = new_session(BOB)
    headers = {} if origin is None else {"Origin": f"http://{url}" if origin == "SAME" else origin}

    async def main() -> None:
        target = f"ws://{url}/sessions/{sid}/stream?key={BOB}"
        if allowed:
            async with websockets.connect(target, additional_headers=headers) as ws:
                await ws.send("{}")
                assert json.loads(await ws.recv())["seq"] == 1
        else:
            with pytest.raises(InvalidStatus) as info:
                async with websockets.connect(target, additional_headers=headers):
                    pass
            assert info.value.response.status_code == 403
            assert b"origin" in info.value.response.body

    asyncio.run(main())


def test_cors_for_allowed_origins_only(http: httpx.Client) -> None:
    pre = {
        "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": "authorization",
    }
    ok = http.options("/sessions", headers={"Origin": "https://app.example.org", **pre})
    assert ok.status_code == 200
    assert ok.headers["access-control-allow-origin"] == "https://app.example.org"
    bad = http.options("/sessions", headers={"Origin": "https://evil.example.com", **pre})
    assert "access-control-allow-origin" not in bad.headers
    r = http.get("/maps", headers={"Origin": "https://app.example.org", **auth(BOB)})
    assert r.headers["access-control-allow-origin"] == "https://app.example.org"


def test_open_mode_only_on_loopback(tmp_path: Path) -> None:
    from app.api.access import StartupRefused

    for host in ("127.0.0.1", "::1", "localhost"):
        create_app(make_settings(host=host))
    with pytest.raises(StartupRefused, match=r"without API keys.*--insecure-open"):
        create_app(make_settings(host="0.0.0.0"))
    create_app(make_settings(host="0.0.0.0", insecure_open=True))
    keys = tmp_path / "keys.txt"
    keys.write_text(KEYS)
    create_app(make_settings(host="0.0.0.0", api_keys_file=keys))
    keys.write_text(f"{ALICE}\nbad line with three\n")
    with pytest.raises(StartupRefused, match="line 2: expected"):
        create_app(make_settings(api_keys_file=keys))


def test_the_command_refuses_to_start_and_says_why(tmp_path: Path) -> None:
    import subprocess
    import sys

    def serve(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "app.cli", "serve", "--no-viser", "--port", "1", *args],
            capture_output=True,
            text=True,
            timeout=120,
        )

    open_ = serve("--host", "0.0.0.0")
    assert open_.returncode == 2
    assert "without API keys" in open_.stderr and "--insecure-open" in open_.stderr
    keys = tmp_path / "keys.txt"
    keys.write_text(f"# comment\n{ALICE}\nname {BOB} 1 2\n")
    bad = serve("--api-keys", str(keys))
    assert bad.returncode == 2
    assert f"{keys}, line 3: expected" in bad.stderr and BOB not in bad.stderr
