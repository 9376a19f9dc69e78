"""Prometheus metrics of one app, in its own registry (tests build many apps)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, disable_created_metrics

disable_created_metrics()


class Metrics:
    """Frames, step latency, sessions."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.frames = Counter("bearings_frames", "Frames processed", registry=self.registry)
        self.frames_accepted = Counter(
            "bearings_frames_accepted",
            "Frames accepted into a session's queue (each is answered, maybe merged)",
            registry=self.registry,
        )
        self.step_seconds = Histogram(
            "bearings_step_seconds",
            "Time to process one frame (filter step and feedback), seconds",
            buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0),
            registry=self.registry,
        )
        self.active_sessions = Gauge(
            "bearings_active_sessions", "Live sessions", registry=self.registry
        )
        self.sessions_created = Counter(
            "bearings_sessions_created", "Sessions created", registry=self.registry
        )
        self.sessions_resumed = Counter(
            "bearings_sessions_resumed",
            "Sessions resumed from the shared session store",
            registry=self.registry,
        )
        self.checkpoints = Counter(
            "bearings_checkpoints", "Session checkpoints written", registry=self.registry
        )
        self.checkpoint_bytes = Counter(
            "bearings_checkpoint_bytes",
            "Bytes of session checkpoints written",
            registry=self.registry,
        )
        self.frames_merged = Counter(
            "bearings_frames_merged",
            "Frames merged into a waiting frame because the session was busy",
            registry=self.registry,
        )
        self.stream_messages = Counter(
            "bearings_stream_messages",
            "WebSocket messages taken in (each gets exactly one answer)",
            registry=self.registry,
        )
        self.stream_answers = Counter(
            "bearings_stream_answers",
            "WebSocket answers sent (results and errors, one per message taken in)",
            registry=self.registry,
        )
        self.store_up = Gauge(
            "bearings_store_up",
            "1 while the shared session store answers (or none is used), 0 while it fails",
            registry=self.registry,
        )
        self.store_up.set(1)
        self.store_failures = Counter(
            "bearings_store_failures",
            "Operations on the shared session store that failed (each is tried again)",
            ["op"],
            registry=self.registry,
        )
        self.frames_not_persisted = Counter(
            "bearings_frames_not_persisted",
            "Frames answered from memory without being stored (state_not_persisted)",
            registry=self.registry,
        )
        self.sessions_behind = Gauge(
            "bearings_sessions_behind",
            "Sessions whose stored state lags what this worker holds (awaiting a checkpoint)",
            registry=self.registry,
        )
        self.sessions_retaken = Counter(
            "bearings_sessions_retaken",
            "Leases taken back after they vanished from the store (nobody else took them)",
            registry=self.registry,
        )
        self.store_recovery_seconds = Gauge(
            "bearings_store_recovery_seconds",
            "After the latest store outage: seconds from the store answering again to "
            "every live session being checkpointed",
            registry=self.registry,
        )
        self.frames_refused = Counter(
            "bearings_frames_refused",
            "Frames refused by a key's rate quota",
            registry=self.registry,
        )
