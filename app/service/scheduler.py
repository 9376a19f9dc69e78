"""Filter steps on the event loop's own thread, shared fairly between clients.

Why not threads: a step is mostly Python around short compiled kernels, so step threads
hold the GIL most of the time and hand it back and forth with each other and with the
event loop at every kernel and every large numpy call. On the 2-vCPU VM this project is
measured on, two step threads made about 26 context switches per frame and cost 2.1 ms
of CPU per frame against 1.2 ms on one thread, for fewer frames per second; a server
with its steps on threads spent about 2.7 ms per frame where the same steps run on the
event loop spend 1.4 ms (benchmarks/README.md, "One worker"). A worker process therefore
uses one core, and more cores are used by more workers (docs/SCALE.md).

Fairness: every client (API key) has its own queue, and the stepper takes one job from
each waiting client in turn (round-robin), so a light client waits at most for the step
that is running and one step of each other waiting client, whatever a heavy client has
queued. Steps run back to back for a slice of at most ``slice_s`` (a few milliseconds),
then the event loop handles whatever I/O is ready: frames are taken in and answers sent
in batches, which costs less per frame than a turn of the loop after every step, and the
answers of a slice's steps go to the session store in one write.
"""

from __future__ import annotations

import asyncio
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Hashable
from typing import Any

Job = tuple[asyncio.Future[Any], Callable[[], Any]]

#: Longest run of steps between two turns of the event loop (seconds). The answers of a
#: slice's steps go to a shared store in one write, so longer slices mean fewer writes:
#: at 120 sessions x 10 Hz, 8 ms served 804-837 frames/s with Redis against 734-747 for
#: 4 ms (memory store 887-926 against 838-875), while a light key's p95 under a heavy
#: key's flood stayed 25-30 ms (benchmarks/abuse.py, three runs; 25.5 ms with 4 ms).
#: 16 ms gained little more and let that light key wait up to 54 ms.
SLICE_S = 0.008
#: Turns of the event loop between two slices. A frame that arrived during a slice
#: needs three to reach the stepper (the socket is read, the stream's reader takes the
#: message, the session's pump submits the step); with fewer, a light key's frame
#: would wait behind one more step of a heavy key (benchmarks/abuse.py: p95 57-65 ms
#: with one turn against 24-28 ms with three).
TURNS = 3


class FairStepper:
    """Runs submitted callables one at a time on the event loop, round-robin between owners.

    Use from the event loop's thread only. ``fair=False`` runs jobs in arrival order.
    """

    def __init__(self, *, fair: bool = True, slice_s: float = SLICE_S) -> None:
        self.fair = fair
        self.slice_s = slice_s
        self._queues: OrderedDict[Hashable, deque[Job]] = OrderedDict()
        self._waiting = 0
        self._stopping = False
        self._wake: asyncio.Event | None = None
        self._task: asyncio.Task[None] | None = None

    @property
    def waiting(self) -> int:
        """Jobs submitted and not yet started."""
        return self._waiting

    def submit(self, owner: Hashable, fn: Callable[..., Any], *args: Any) -> asyncio.Future[Any]:
        """Queue ``fn(*args)`` behind ``owner``'s earlier jobs; a future of its result."""
        if self._stopping:
            raise RuntimeError("the stepper is shut down")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Any] = loop.create_future()
        key = owner if self.fair else None
        queue = self._queues.get(key)
        if queue is None:
            queue = self._queues[key] = deque()
        queue.append((future, lambda: fn(*args)))
        self._waiting += 1
        if self._task is None or self._task.done() or self._task.get_loop() is not loop:
            self._wake = asyncio.Event()
            self._task = loop.create_task(self._run(), name="filter-steps")
        assert self._wake is not None
        self._wake.set()
        return future

    def _next(self) -> Job | None:
        if not self._queues:
            return None
        owner, queue = next(iter(self._queues.items()))
        job = queue.popleft()
        del self._queues[owner]
        if queue:
            self._queues[owner] = queue  # back of the line
        self._waiting -= 1
        return job

    async def _run(self) -> None:
        assert self._wake is not None
        turn_ends = time.perf_counter() + self.slice_s
        while True:
            job = self._next()
            if job is None:
                self._wake.clear()
                await self._wake.wait()
                turn_ends = time.perf_counter() + self.slice_s
                continue
            future, call = job
            if not future.cancelled():
                try:
                    result = call()
                except Exception as exc:  # the job's caller gets it; the stepper goes on
                    future.set_exception(exc)
                else:
                    future.set_result(result)
            if time.perf_counter() >= turn_ends:
                # Let the event loop take in frames and send answers.
                for _ in range(TURNS):
                    await asyncio.sleep(0)
                turn_ends = time.perf_counter() + self.slice_s

    def shutdown(self) -> None:
        """Take no more jobs; cancel the ones not started (for a closing service)."""
        self._stopping = True
        for queue in self._queues.values():
            for future, _ in queue:
                future.cancel()
        self._queues.clear()
        self._waiting = 0
        if self._task is not None and not self._task.get_loop().is_closed():
            self._task.cancel()
