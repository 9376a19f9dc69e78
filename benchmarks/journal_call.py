"""What one journal write costs the worker's CPU: one call of the append script.

Times ``time.thread_time()`` around ``_OnLoop._write(batch)`` (the group commit's one
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

from app.service.store import _APPEND, Entry, _keys, _OnLoop

_APPEND_SHA = hashlib.sha1(_APPEND.encode()).hexdigest()


class _RedisPyJournal(_OnLoop):
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
                await self.client.script_load(_APPEND)
            except BaseException as exc:
                self._redis_py_conn = None
                await conn.disconnect()
                await self.pool.release(conn)
                conn = None
                if attempt or not isinstance(exc, ConnectionError):
                    raise
        raise AssertionError("unreachable")


async def _calls(writer: _OnLoop, batch: list[Entry], n: int, between: int) -> list[float]:
    out = []
    scratch = np.ones(between // 8)
    for _ in range(n):
        if between:
            scratch *= 1.0000001  # other work between writes: the caches go cold
        t = time.thread_time()
        ok = await writer._write(batch)
        out.append(time.thread_time() - t)
        assert all(ok), "an append was refused: its lease is missing"
    return out


async def main(args: argparse.Namespace) -> None:
    loop = asyncio.get_running_loop()
    writers: dict[str, _OnLoop] = {"store": _OnLoop(args.store, 5.0, loop)}
    if args.redis_py:
        writers["redis-py"] = _RedisPyJournal(args.store, 5.0, loop)
    entry = b"5|" + b"x" * 900
    batches = {
        n: [(f"bench{i}", entry, "bench", 60_000, 60_000) for i in range(n)] for n in args.batch
    }
    client = writers["store"].client
    sessions = max(args.batch)
    for i in range(sessions):
        await client.set(_keys(f"bench{i}")[0], "bench", px=600_000)
    times: dict[tuple[str, int], list[float]] = {}
    try:
        for writer in writers.values():  # warm up: connect, load the script
            await _calls(writer, batches[1], 20, 0)
        for _ in range(args.rounds):
            for n, batch in batches.items():
                for name, writer in writers.items():
                    times.setdefault((name, n), []).extend(
                        await _calls(writer, batch, args.calls, args.between)
                    )
                    # keep the journal short (RPUSH on a long list costs Redis, not us)
                    await client.delete(*[_keys(f"bench{i}")[2] for i in range(n)])
    finally:
        await client.delete(*[k for i in range(sessions) for k in _keys(f"bench{i}")])
        for writer in writers.values():
            await writer.aclose()
    print(f"CPU per call (median of {args.rounds} x {args.calls} calls), us")
    print(f"{'batch':>6} " + " ".join(f"{name:>10}" for name in writers))
    for n in batches:
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
