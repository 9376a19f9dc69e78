"""Filter steps on a few threads, shared fairly between clients.

A plain thread pool runs jobs in arrival order, so a client that keeps many heavy
sessions busy makes everyone else wait behind all of its steps. Here every client
(API key) has its own queue and the threads take one job from each waiting client in
turn (round-robin): a light client waits at most for the steps already running, one per
thread, whatever a heavy client has queued.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Hashable
from concurrent.futures import Future
from typing import Any


class FairExecutor:
    """``workers`` threads running submitted callables, round-robin between ``owner`` queues."""

    def __init__(
        self, workers: int, *, max_per_owner: int | None = None, name: str = "step"
    ) -> None:
        self.max_per_owner = max(1, max_per_owner or workers)
        self._running_of: dict[Hashable, int] = {}
        self._queues: OrderedDict[Hashable, deque[tuple[Future[Any], Callable[[], Any], float]]]
        self._queues = OrderedDict()
        self._cv = threading.Condition()
        self._stopping = False
        self._waiting = 0
        self._running = 0
        #: Seconds the last started job waited for a thread.
        self.last_wait_s = 0.0
        self._threads = [
            threading.Thread(target=self._work, name=f"{name}-{i}", daemon=True)
            for i in range(max(1, workers))
        ]
        for t in self._threads:
            t.start()

    @property
    def waiting(self) -> int:
        """Jobs submitted and not yet started."""
        return self._waiting

    @property
    def running(self) -> int:
        return self._running

    def submit(self, owner: Hashable, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        """Queue ``fn(*args)`` behind ``owner``'s earlier jobs; a future of its result."""
        future: Future[Any] = Future()
        with self._cv:
            if self._stopping:
                raise RuntimeError("the step executor is shut down")
            queue = self._queues.get(owner)
            if queue is None:
                queue = self._queues[owner] = deque()
            queue.append((future, lambda: fn(*args), time.monotonic()))
            self._waiting += 1
            self._cv.notify()
        return future

    def _next(self) -> tuple[Hashable, tuple[Future[Any], Callable[[], Any], float]] | None:
        with self._cv:
            while True:
                # The owner served longest ago that is not already using its share of
                # the threads.
                eligible = [
                    o for o in self._queues if self._running_of.get(o, 0) < self.max_per_owner
                ]
                if eligible:
                    owner = eligible[0]
                    break
                if self._stopping and not self._queues:
                    return None
                self._cv.wait()
            queue = self._queues.pop(owner)
            job = queue.popleft()
            if queue:
                self._queues[owner] = queue  # back of the line
            self._waiting -= 1
            self._running += 1
            self._running_of[owner] = self._running_of.get(owner, 0) + 1
            return owner, job

    def _work(self) -> None:
        while True:
            taken = self._next()
            if taken is None:
                return
            owner, (future, call, queued_at) = taken
            self.last_wait_s = time.monotonic() - queued_at
            try:
                if future.set_running_or_notify_cancel():
                    try:
                        result = call()
                    except BaseException as exc:
                        future.set_exception(exc)
                    else:
                        future.set_result(result)
            finally:
                with self._cv:
                    self._running -= 1
                    left = self._running_of[owner] - 1
                    if left:
                        self._running_of[owner] = left
                    else:
                        del self._running_of[owner]
                    self._cv.notify_all()  # an owner at its share may go again

    def shutdown(self, *, wait: bool = True, cancel_futures: bool = False) -> None:
        """Stop taking jobs; run (or cancel) the queued ones; with ``wait``, join the threads."""
        with self._cv:
            self._stopping = True
            if cancel_futures:
                for queue in self._queues.values():
                    for future, _, _ in queue:
                        future.cancel()
                self._queues.clear()
                self._waiting = 0
            self._cv.notify_all()
        if wait:
            for t in self._threads:
                t.join()
