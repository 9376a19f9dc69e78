"""What one journal write costs the worker's CPU: one call of the append script.

Times ``time.thread_time()`` around ``LoopWriter._write(batch)`` (the group commit's one
call per batch) for batches of 1, 4 and 12 entries of 900 bytes, on uvloop as
``bearings serve`` runs, and prints the median over the calls. The time the loop spends
idle waiting for Redis is not CPU and does not count; Redis's own CPU does not count.
``--redis-py`` times the same calls made through a redis-py asyncio connection as well
(the journal's path before its own connection), round by round alternately with the
store's, so that both sets of figures come from the same run.

    redis-server --port 6391 --save "" --appendonly no --daemonize yes
    python benchmarks/journal_call.py --store redis://127.0.0.1:6391/0 --redis-py

The figures depend on where Redis runs: on the same core as the script (``taskset -p
-c 0 REDIS_PID``, then ``taskset -c 0 python ...``) a call costs the least; with Redis on
another core that sits idle, waking up for each reply adds 20-30 us to every call (on a
2-vCPU virtual machine). ``--between 4000000`` writes 4 MB between calls, as a worker
stepping its sessions between journal writes does, and the caches go cold.
"""

from __future__ import annotations

import argparse
import asyncio
import hashlib
import statistics
import time

import numpy as np
import uvloop

from app.service.store import Hold
from app.service.store.group_commit import Entry
from app.service.store.scripts import APPEND, base_key
from app.service.store.writer import LoopWriter

_APPEND_SHA = hashlib.sha1(APPEND.encode()).hexdigest()


class _RedisPyJournal(LoopWriter):
    """The journal's call as it was made through redis-py: its asyncio connection (held
    by the group commit), the command packed by hiredis."""

    async def _append_call(self, keys: list[str], args: list[bytes | str | int]) -> list[int]:
        import hiredis
        from redis.exceptions import ConnectionError, NoScriptError

        command = hiredis.pack_command(("EVALSHA", _APPEND_SHA, len(keys), *keys, *args))  # type: ignore[arg-type]
        conn = getattr(self, "_redis_py_conn", None)
        for attempt in range(2):
            if conn is None:
                conn = self._redis_py_conn = await self.pool.get_connection()
            try:
                await conn.send_packed_command(command, check_health=False)
                reply: list[int] = await conn.read_response()
                return reply
            except NoScriptError:
                if attempt:
                    raise
                await self.client.script_load(APPEND)
            except BaseException as exc:
                self._redis_py_conn = None
                await conn.disconnect()
                await self.pool.release(conn)
                conn = None
                if attempt or not isinstance(exc, ConnectionError):
                    raise
        raise AssertionError("unreachable")


def _batches(sessions: int, calls: int) -> list[list[Entry]]:
    """``calls`` batches of one entry per session, the frames numbered on from 1 (the
    store writes an entry only right after the stored frames)."""
    payload = b"x" * 900
    return [
        [(f"bench{i}", b"%d|" % seq + payload, "bench", 1, 60_000, 60_000) for i in range(sessions)]
        for seq in range(1, calls + 1)
    ]


async def _calls(writer: LoopWriter, sessions: int, n: int, between: int) -> list[float]:
    out = []
    scratch = np.ones(between // 8)
    for batch in _batches(sessions, n):
        if between:
            scratch *= 1.0000001  # other work between writes: the caches go cold
        t = time.thread_time()
        holds = await writer._write(batch)
        out.append(time.thread_time() - t)
        assert all(h == Hold.HELD for h in holds), f"an append was refused: {holds}"
    return out


async def main(args: argparse.Namespace) -> None:
    loop = asyncio.get_running_loop()
    writers: dict[str, LoopWriter] = {"store": LoopWriter(args.store, 5.0, loop)}
    if args.redis_py:
        writers["redis-py"] = _RedisPyJournal(args.store, 5.0, loop)
    client = writers["store"].client
    sessions = max(args.batch)
    for i in range(sessions):  # the lease, its fencing token, a checkpoint of frame 0
        base = base_key(f"bench{i}")
        await client.set(f"{base}:lease", "bench", px=600_000)
        await client.set(f"{base}:fence", 1, px=600_000)
        await client.set(f"{base}:ckpt:frames", 0, px=600_000)
    times: dict[tuple[str, int], list[float]] = {}
    try:
        for writer in writers.values():  # warm up: connect, load the script
            await _calls(writer, 1, 20, 0)
            await client.delete(f"{base_key('bench0')}:journal")
        for _ in range(args.rounds):
            for n in args.batch:
                for name, writer in writers.items():
                    times.setdefault((name, n), []).extend(
                        await _calls(writer, n, args.calls, args.between)
                    )
                    # keep the journal short (RPUSH on a long list costs Redis, not us),
                    # and numbered on from the checkpoint's frame 0 again
                    await client.delete(*[f"{base_key(f'bench{i}')}:journal" for i in range(n)])
    finally:
        await client.delete(
            *[
                f"{base_key(f'bench{i}')}:{k}"
                for i in range(sessions)
                for k in ("lease", "fence", "ckpt:frames", "journal")
            ]
        )
        for writer in writers.values():
            await writer.aclose()
    print(f"CPU per call (median of {args.rounds} x {args.calls} calls), us")
    print(f"{'batch':>6} " + " ".join(f"{name:>10}" for name in writers))
    for n in args.batch:
        row = [1e6 * statistics.median(times[name, n]) for name in writers]
        print(f"{n:>6} " + " ".join(f"{v:>10.1f}" for v in row))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--store", default="redis://127.0.0.1:6379/0", help="a redis:// URL")
    parser.add_argument("--batch", type=int, nargs="+", default=[1, 4, 12])
    parser.add_argument("--calls", type=int, default=100, help="calls per round")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--between", type=int, default=0, help="bytes of memory written between calls"
    )
    parser.add_argument("--redis-py", action="store_true", help="the redis-py path as well")
    uvloop.run(main(parser.parse_args()))
