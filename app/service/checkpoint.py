"""A session's checkpoint and its journal of frames, as bytes for a session store.

A checkpoint holds everything a session needs to go on elsewhere: how it was created
(its :class:`~app.service.types.SessionSpec`), the filter's state
(:meth:`ParticleFilter.checkpoint`: at most 2,000 particles as float32, the recovery
averages, the convergence gate, the alternative hypotheses' tracker, the random
generator), the narrator's memory (:meth:`Narrator.checkpoint`), the guidance speaker's,
the destination, the owner, the frame count and the latest result. Each part serializes
itself, the session assembles them (:meth:`~app.service.session.Session.capture`) and
takes them back (:meth:`~app.service.session.Session.restore`); this module packs them
into bytes and reads them back.

Checkpoints are written about once a second; every frame answered since the last one is
kept in a journal (one short entry per frame) and replayed on resume, so a session
resumed on another worker has seen exactly the frames its client was answered for.

Bytes: ``BRGC1``, a 4-byte little-endian header length, the header, then the raw arrays
the header points to (dtype, shape, offset). Anything numerous is an array (the
particles, the main mode's trail, the window's observations as columns), so the header
stays a few KB: a checkpoint of a converged session (2,000 particles, the evidence
tracker's window of 10 observations) is about 39.5 KB on the office walk of
benchmarks/load.py (43 KB in format 3, which measured 40 to 57 KB over other walks).

Formats: 4 keeps the evidence window's observations as the few arrays they are made of
(:func:`~app.localization.sensor.observation_columns`), its odometry as rows, and the
last detections as rows: a checkpoint of a converged session takes about half the time
to capture and pack as in format 3 (benchmarks/README.md). 3 wrote the header in
MessagePack, whose numbers are binary (JSON spent most of a checkpoint's packing writing
a hundred-odd floats out in decimal). 2 and 1 wrote JSON (a header opening with ``{``);
1 kept the evidence window as one plain record per frame rather than as columns. All
four are read, so sessions checkpointed by an older version resume on upgraded workers.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Mapping
from datetime import datetime
from typing import Any

import msgpack
import numpy as np
import orjson

from app.service.types import FrameInput, SessionSpec
from app.state import from_plain, plain_step

MAGIC = b"BRGC1"
FORMAT_VERSION = 4
#: Formats this version reads: 1 and 2 have a JSON header (1 differs in the evidence
#: window), 3 and 4 a MessagePack one (4 differs in the evidence window and the last
#: detections).
READABLE_FORMATS = (1, 2, 3, 4)
_ARRAY = "__array__"


class BadCheckpoint(ValueError):
    """Bytes that are not a checkpoint this version can read."""


def pack(state: Mapping[str, Any]) -> bytes:
    """Nested data with numpy arrays anywhere in it, as bytes. Dataclasses, mappings and
    numpy scalars are converted on the way (:func:`~app.state.plain_step`) as the
    encoder's compiled walk meets them, so nothing walks the whole state in Python.
    Integers must fit in 64 bits."""
    blobs: list[memoryview] = []  # the arrays' own memory, copied once: by the join
    offset = 0

    def convert(value: Any) -> Any:
        nonlocal offset
        if isinstance(value, np.ndarray):
            data = np.ascontiguousarray(value)
            ref = {_ARRAY: [value.dtype.str, list(value.shape), offset]}
            blobs.append(data.data)
            offset += data.nbytes
            return ref
        return plain_step(value)

    header = msgpack.packb(state, default=convert)
    return b"".join([MAGIC, struct.pack("<I", len(header)), header, *blobs])


def unpack(data: bytes) -> dict[str, Any]:
    """The state :func:`pack` was given, as plain data (arrays read-only, backed by
    ``data``; dataclasses as dicts of their fields)."""
    if not data.startswith(MAGIC) or len(data) < len(MAGIC) + 4:
        raise BadCheckpoint("not a Bearings checkpoint (wrong magic bytes)")
    (size,) = struct.unpack_from("<I", data, len(MAGIC))
    start = len(MAGIC) + 4
    body = memoryview(data)[start + size :]

    def array(value: dict[str, Any]) -> Any:
        if _ARRAY not in value:
            return value
        dtype, shape, offset = value[_ARRAY]
        count = math.prod(shape)
        return np.frombuffer(body, dtype=dtype, count=count, offset=offset).reshape(shape)

    header = data[start : start + size]
    try:
        if header.startswith(b"{"):  # formats 1 and 2
            state: dict[str, Any] = json.loads(header, object_hook=array)
        else:
            state = msgpack.unpackb(header, object_hook=array, strict_map_key=True)
    except (ValueError, msgpack.UnpackException) as exc:
        raise BadCheckpoint(f"checkpoint header unreadable: {exc}") from None
    if not isinstance(state, dict):
        raise BadCheckpoint("checkpoint header unreadable: not a mapping")
    if state.get("format") not in READABLE_FORMATS:
        raise BadCheckpoint(
            f"checkpoint format {state.get('format')!r}; this version reads "
            f"{', '.join(map(str, READABLE_FORMATS))}"
        )
    return state


def spec_of(state: Mapping[str, Any]) -> SessionSpec:
    """The spec a checkpointed session was created from (to build it again)."""
    spec: SessionSpec = from_plain(SessionSpec, state["spec"])
    return spec


def created_at_of(state: Mapping[str, Any]) -> datetime:
    return datetime.fromisoformat(state["created_at"])


#: The fields of :class:`FrameInput` a journal entry holds, in its order (a test holds
#: this to the dataclass, so a field added there cannot be left out here unnoticed).
ENTRY_FIELDS = (
    "timestamp",
    "odometry",
    "detections",
    "describe",
    "truth",
    "heading",
    "detections_age_s",
    "altitude",
)


def encode_frame(seq: int, frame: FrameInput, merged: int = 1) -> bytes:
    """One journal entry: the step's sequence number, then the frame (``merged`` frames
    merged into one) as a JSON array: ``[merged, timestamp, odometry, detections,
    describe, truth, heading, detections_age_s]`` and, when the frame has one,
    ``altitude`` (a venue's barometer: frames without one are written as before it),
    each detection a row ``[class, bearing, score]`` and the other values as
    :func:`~app.state.to_plain` writes them.

    Every frame a shared store journals is encoded here, on the event loop. The
    detections as rows, rather than one object each, take orjson 1 us instead of 5 for
    a frame of 11 (benchmarks/README.md); the rest is orjson's compiled walk of the
    dataclasses. Only finite numbers reach it (the API refuses any other,
    :mod:`app.validation`); anything that is not plain data (a numpy scalar) goes
    through :func:`~app.state.plain_step`."""
    rows = [[d.cls, d.bearing_rad, d.score] for d in frame.detections]
    f = frame
    body: list[object] = [merged, f.timestamp, f.odometry, rows, f.describe, f.truth, f.heading]
    body.append(f.detections_age_s)
    if f.altitude is not None:
        body.append(f.altitude)
    return b"%d|" % seq + orjson.dumps(body, default=plain_step)


def decode_frame(entry: bytes) -> tuple[int, FrameInput, int]:
    """The sequence number, frame and merge count of an entry :func:`encode_frame`
    wrote, or an entry of the earlier form (``{"frame": ..., "merged": n}``, the frame
    as :func:`~app.state.to_plain` wrote it) that a journal may still hold."""
    seq, _, raw = entry.partition(b"|")
    body = orjson.loads(raw)
    if isinstance(body, dict):
        return int(seq), from_plain(FrameInput, body["frame"]), int(body["merged"])
    merged, *values = body
    # Entries written before detections had an age hold the first six values only;
    # the altitude is there only when the frame had one.
    if len(values) not in (len(ENTRY_FIELDS) - 2, len(ENTRY_FIELDS) - 1, len(ENTRY_FIELDS)):
        raise ValueError(f"a journal entry of {len(values)} values is no frame")
    plain = dict(zip(ENTRY_FIELDS[: len(values)], values, strict=True))
    plain["detections"] = [
        {"cls": c, "bearing_rad": b, "score": s} for c, b, s in plain["detections"]
    ]
    return int(seq), from_plain(FrameInput, plain), int(merged)
