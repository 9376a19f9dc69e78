"""Checkpoints: each part restores itself, a session resumes where it was, nothing repeats.

Two managers sharing one in-process store (``MemoryStore(shared=True)``, the same
semantics as Redis) stand for two workers.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import math
import struct
from typing import Any

import numpy as np
import pytest

from app.feedback import FeedbackOptions, Narrator
from app.guidance.planner import plan_for
from app.guidance.targets import DestinationSpec
from app.localization.compass import CompassReading
from app.localization.config import FilterConfig
from app.localization.filter import CHECKPOINT_PARTICLES, ParticleFilter
from app.localization.floors import AltitudeReading
from app.localization.sensor import (
    Observation,
    observation_columns,
    observations_from_columns,
    prepare_observation,
)
from app.localization.types import Detection, InitialPose, Odometry, Pose
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.service import checkpoint
from app.service.errors import SessionNotFound, SessionUnavailable
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.sharing import rebuild
from app.service.store import MemoryStore
from app.service.types import FrameInput, FrameOutcome, SensorSpec, SessionSpec
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate
from app.state import from_columns, from_plain, plain_step, to_columns, to_plain
from tests.helpers import make_settings

OFFICE = load_map(bundled_maps_dir() / "paper_office.json")
WALK = simulate(OFFICE, paper_config("nominal", 360), np.random.default_rng(5))


def frame(i: int) -> FrameInput:
    f = WALK[i]
    return FrameInput(
        timestamp=f.t, odometry=f.odometry, detections=tuple(f.detections), truth=f.truth
    )


def round_trip(state: object) -> Any:
    """``state`` packed into a checkpoint and unpacked again."""
    packed = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "state": state})
    return checkpoint.unpack(packed)["state"]


def test_plain_data_round_trip_of_a_full_spec_and_an_outcome() -> None:
    spec = SessionSpec(
        map_name="paper_office",
        particles=3000,
        seed=7,
        initial_pose=InitialPose(1.0, 2.0, 0.5, 0.2, 0.1),
        sensor=SensorSpec(3.0, 180.0, {"door": 4.0}),
        feedback=FeedbackOptions("left_right", "imperial", 2),
    )
    assert from_plain(SessionSpec, to_plain(spec)) == spec
    pf = ParticleFilter(OFFICE, FilterConfig(particles=500), rng=np.random.default_rng(0))
    estimate = pf.step(WALK[1].odometry, WALK[1].detections)
    narrator = Narrator(OFFICE)
    feedback = narrator.update(estimate, WALK[1].detections, timestamp_s=0.2)
    outcome = FrameOutcome(3, estimate, feedback, ("a warning",), ("Kitchen", None, None))
    assert from_plain(FrameOutcome, to_plain(outcome)) == outcome
    assert from_plain(FrameInput, to_plain(frame(3))) == frame(3)
    # A journal entry holds every field of the frame, and reads back the same.
    assert tuple(f.name for f in dataclasses.fields(FrameInput)) == checkpoint.ENTRY_FIELDS
    frames = (
        frame(3),
        FrameInput(),
        FrameInput(heading=CompassReading(1.0, 0.2), truth=Pose(1.0, 2.0, -0.5)),
        FrameInput(timestamp=np.float64(0.1) + 0.2, detections=(Detection("door", 0.1, 0.9),)),
        FrameInput(detections=(Detection("door", np.float64(0.25), 1),), describe=True),
        FrameInput(altitude=AltitudeReading(12.5, 0.4)),
    )
    for f in frames:
        entry = checkpoint.encode_frame(7, f, 2)
        assert entry.startswith(b"7|[2,")
        assert checkpoint.decode_frame(entry) == (7, f, 2)
        # Entries of the earlier form (the frame as an object) still read.
        earlier = json.dumps({"frame": to_plain(f), "merged": 2}, separators=(",", ":"))
        assert checkpoint.decode_frame(b"7|" + earlier.encode()) == (7, f, 2)


def test_from_plain_says_what_does_not_fit() -> None:
    with pytest.raises(TypeError, match="expected a number"):
        from_plain(InitialPose, {"x": "one", "y": 0.0, "theta_rad": 0.0})


def test_filter_restored_from_its_checkpoint_goes_on_the_same_way() -> None:
    config = FilterConfig(particles=4000)
    a = ParticleFilter(OFFICE, config, rng=np.random.default_rng(3))
    for i in range(40):
        a.step(WALK[i].odometry, WALK[i].detections)
    assert a.estimate.converged and a.n <= CHECKPOINT_PARTICLES
    data = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "filter": a.checkpoint()})
    assert len(data) < 64_000  # "a few tens of KB" (docs/SCALE.md sizes Redis with it)
    b = ParticleFilter(OFFICE, config, rng=np.random.default_rng(99))
    b.restore(checkpoint.unpack(data)["filter"])
    assert b.estimate == a.estimate and b.n == a.n
    # The walk a gain is tested against (app.localization.walked) came along, to float32.
    assert b.walked.walked_m == a.walked.walked_m > 0.0
    np.testing.assert_allclose(
        b.walked.checkpoint()["points"], a.walked.checkpoint()["points"], rtol=0, atol=0
    )
    for i in range(40, 60):
        ea = a.step(WALK[i].odometry, WALK[i].detections)
        eb = b.step(WALK[i].odometry, WALK[i].detections)
        # Same particles up to float32 rounding, same random draws: the same path.
        assert math.hypot(ea.x - eb.x, ea.y - eb.y) < 1e-3
        assert ea.converged == eb.converged


def _pack_with_a_json_header(state: dict[str, Any]) -> bytes:
    """What the version that wrote formats 1 and 2 wrote: a JSON header (arrays as raw
    bytes after it), the generator's state with its 128-bit integers as numbers."""
    blobs: list[bytes] = []

    def convert(value: Any) -> Any:
        if isinstance(value, np.ndarray):
            offset = sum(map(len, blobs))
            blobs.append(np.ascontiguousarray(value).tobytes())
            return {"__array__": [value.dtype.str, list(value.shape), offset]}
        return plain_step(value)

    rng = state["filter"]["rng"]
    rng = {**rng, "state": {k: int(v) for k, v in rng["state"].items()}}
    state = {**state, "filter": {**state["filter"], "rng": rng}}
    header = json.dumps(state, default=convert, separators=(",", ":")).encode()
    return b"".join([checkpoint.MAGIC, struct.pack("<I", len(header)), header, *blobs])


def _format_3_window(pf: ParticleFilter) -> dict[str, Any]:
    """The evidence window as formats 2 and 3 kept it: the odometry as records, every
    field of the observations as columns (:func:`to_columns`)."""
    assert pf.evidence is not None
    history = list(pf.evidence._history)
    assert history  # the window holds frames, so the old layout is exercised
    return {
        "odometry": [to_plain(odo) for odo, _, _ in history],
        "observations": to_columns([obs for _, obs, _ in history]),
        "compass": [to_plain(compass) for _, _, compass in history],
    }


@pytest.mark.parametrize("version", [1, 3])
def test_a_checkpoint_of_an_earlier_format_is_still_read(version: int) -> None:
    """Format 1 kept the evidence window as one plain record per frame, 3 every field of
    its observations as columns; a session checkpointed by an earlier version must
    resume on an upgraded worker, exactly as from the current format."""
    config = FilterConfig(particles=4000)
    a = ParticleFilter(OFFICE, config, rng=np.random.default_rng(3))
    for i in range(40):
        a.step(WALK[i].odometry, WALK[i].detections)
    state = round_trip(a.checkpoint())
    window = _format_3_window(a)
    if version == 1:
        observations = from_columns(Observation, window["observations"])
        records = zip(window["odometry"], observations, window["compass"], strict=True)
        state["evidence"]["history"] = [[odo, to_plain(obs), c] for odo, obs, c in records]
        data = _pack_with_a_json_header({"format": 1, "filter": state})
    else:
        state["evidence"]["history"] = window
        data = checkpoint.pack({"format": 3, "filter": state})
    b = ParticleFilter(OFFICE, config, rng=np.random.default_rng(99))
    b.restore(checkpoint.unpack(data)["filter"])
    c = ParticleFilter(OFFICE, config, rng=np.random.default_rng(99))
    c.restore(round_trip(a.checkpoint()))
    assert b.evidence is not None and c.evidence is not None
    assert len(b.evidence._history) == len(c.evidence._history)
    for i in range(40, 60):
        eb = b.step(WALK[i].odometry, WALK[i].detections)
        ec = c.step(WALK[i].odometry, WALK[i].detections)
        assert eb == ec  # the same state, whichever format it came in


def test_the_evidence_window_comes_back_as_it_was() -> None:
    """Frames without odometry and with a compass reading in the window too."""
    pf = ParticleFilter(OFFICE, FilterConfig(particles=3000), rng=np.random.default_rng(5))
    for i in range(30):
        odometry = None if i % 4 == 3 else WALK[i].odometry
        heading = CompassReading(WALK[i].truth.theta_rad, 0.2) if i % 3 == 0 else None
        pf.step(odometry, WALK[i].detections, heading)
    twin = ParticleFilter(OFFICE, FilterConfig(particles=3000), rng=np.random.default_rng(6))
    twin.restore(round_trip(pf.checkpoint()))
    assert pf.evidence is not None and twin.evidence is not None
    window, back = list(pf.evidence._history), list(twin.evidence._history)
    assert [odo for odo, _, _ in back] == [odo for odo, _, _ in window]
    assert [c for _, _, c in back] == [c for _, _, c in window]
    assert None in [odo for odo, _, _ in window] and any(c for _, _, c in window)
    _assert_same_observations([o for _, o, _ in window], [o for _, o, _ in back])


def test_a_format_2_checkpoint_with_a_json_header_is_still_read() -> None:
    config = FilterConfig(particles=4000)
    a = ParticleFilter(OFFICE, config, rng=np.random.default_rng(3))
    for i in range(40):
        a.step(WALK[i].odometry, WALK[i].detections)
    state = a.checkpoint()
    assert any(isinstance(v, str) for v in state["rng"]["state"].values())  # 128-bit
    old = _pack_with_a_json_header({"format": 2, "filter": state})
    new = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "filter": state})
    assert not new[len(checkpoint.MAGIC) + 4 :].startswith(b"{")
    b = ParticleFilter(OFFICE, config, rng=np.random.default_rng(98))
    b.restore(checkpoint.unpack(old)["filter"])
    c = ParticleFilter(OFFICE, config, rng=np.random.default_rng(99))
    c.restore(checkpoint.unpack(new)["filter"])
    for i in range(40, 60):
        eb = b.step(WALK[i].odometry, WALK[i].detections)
        ec = c.step(WALK[i].odometry, WALK[i].detections)
        assert eb == ec  # the same state, whichever header it came in


def test_numbers_come_back_exactly_from_a_header() -> None:
    values = [0.1, -0.0, 1e-310, math.pi, math.inf, -math.inf, 2**63 - 1, -(2**63), True]
    back = checkpoint.unpack(checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "v": values}))
    assert back["v"] == values and math.copysign(1, back["v"][1]) == -1
    nan = checkpoint.unpack(checkpoint.pack({"format": 3, "v": math.nan}))["v"]
    assert math.isnan(nan)
    with pytest.raises(checkpoint.BadCheckpoint, match="unreadable"):
        checkpoint.unpack(checkpoint.MAGIC + struct.pack("<I", 3) + b"\xc1\xc1\xc1")


def test_a_lost_filter_is_checkpointed_on_a_subsample() -> None:
    pf = ParticleFilter(OFFICE, FilterConfig(particles=10_000), rng=np.random.default_rng(1))
    pf.step(WALK[0].odometry, WALK[0].detections)
    state = pf.checkpoint()
    assert state["x"].shape == (CHECKPOINT_PARTICLES,) and state["log_w"] is None
    restored = ParticleFilter(OFFICE, FilterConfig(particles=10_000), rng=np.random.default_rng(2))
    restored.restore(round_trip(state))
    assert restored.n == CHECKPOINT_PARTICLES
    restored.step(WALK[1].odometry, WALK[1].detections)
    assert restored.n == 10_000  # lost again: grows back to the configured count


def test_narrator_restored_does_not_repeat_itself() -> None:
    pf = ParticleFilter(OFFICE, FilterConfig(particles=2000), rng=np.random.default_rng(3))
    narrator = Narrator(OFFICE)
    for i in range(30):
        est = pf.step(WALK[i].odometry, WALK[i].detections)
        narrator.update(est, WALK[i].detections, timestamp_s=WALK[i].t)
    twin = Narrator(OFFICE)
    twin.restore(round_trip(narrator.checkpoint()))
    est = pf.step(WALK[30].odometry, WALK[30].detections)
    said = narrator.update(est, WALK[30].detections, timestamp_s=WALK[30].t)
    again = twin.update(est, WALK[30].detections, timestamp_s=WALK[30].t)
    assert again == said
    assert "Location found" not in again.text


def test_bad_bytes_are_refused_with_a_reason() -> None:
    with pytest.raises(checkpoint.BadCheckpoint, match="magic"):
        checkpoint.unpack(b"not a checkpoint")
    with pytest.raises(checkpoint.BadCheckpoint, match="format"):
        checkpoint.unpack(checkpoint.pack({"format": 99}))


def _assert_same_observations(a: list[Observation], b: list[Observation]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        for f in dataclasses.fields(Observation):
            vx, vy = getattr(x, f.name), getattr(y, f.name)
            if isinstance(vx, np.ndarray):
                assert vx.dtype == vy.dtype and np.array_equal(vx, vy), f.name
                assert vy.flags.writeable and vy.flags.c_contiguous
            else:
                assert vx == vy, f.name


@pytest.mark.parametrize("clutter", [True, False])
def test_observations_as_columns_come_back_exactly(clutter: bool) -> None:
    config = FilterConfig(clutter=clutter, class_bearing_std_deg={"door": 5.0})
    frames = [*WALK[:4], WALK[4]]
    detections = [list(f.detections) for f in frames]
    detections[3] = []  # a frame with nothing usable ...
    detections[4].append(Detection("unicorn", 0.5, 1.0))  # ... and one with a stranger
    detections[1].append(Detection("door", 0.3, 0.0))  # a score of 0 carries nothing
    observations = [prepare_observation(d, OFFICE, config) for d in detections]
    assert any(len(set(o.det_group.tolist())) < o.det_group.size for o in observations)
    for packed in (False, True):
        # Every field (format 3) ...
        columns = to_columns(observations)
        back = from_columns(Observation, round_trip(columns) if packed else columns)
        _assert_same_observations(observations, back)
        # ... and what they are made of (format 4), the rest taken from the map.
        compact = observation_columns(observations)
        compact = round_trip(compact) if packed else compact
        _assert_same_observations(observations, observations_from_columns(compact, OFFICE, config))
    assert from_columns(Observation, round_trip(to_columns([]))) == []
    assert observations_from_columns(round_trip(observation_columns([])), OFFICE, config) == []


def test_pack_converts_values_on_the_way() -> None:
    state = {
        "detection": Detection("door", 0.25, 1.0),
        "count": np.int64(3),
        "pose": (1.0, float("nan")),
        "grid": np.arange(6, dtype=np.float32).reshape(2, 3),
        "none": np.zeros(0, dtype=bool),
    }
    back = round_trip(state)
    assert back["detection"] == {"cls": "door", "bearing_rad": 0.25, "score": 1.0}
    assert from_plain(Detection, back["detection"]) == state["detection"]
    assert back["count"] == 3 and back["pose"][0] == 1.0 and math.isnan(back["pose"][1])
    assert back["grid"].dtype == np.float32 and np.array_equal(back["grid"], state["grid"])
    assert back["none"].shape == (0,) and back["none"].dtype == bool


def test_a_restored_session_steps_exactly_as_the_original() -> None:
    """Same particles, estimates, feedback and guidance, to the bit: the checkpoints of
    the two sessions after 20 more frames are the same bytes."""
    m = manager(MemoryStore(shared=True))
    a = m.build(SPEC)
    a.set_destination(plan_for(OFFICE, DestinationSpec("label", "main entrance")))
    for i in range(40):
        a.process_sync(frame(i))
    assert a.filter.estimate.converged and a.filter.n <= CHECKPOINT_PARTICLES
    state = checkpoint.unpack(checkpoint.pack(a.capture()))
    b = rebuild(m, state)
    for name in ("x", "y", "theta", "log_w"):
        assert np.array_equal(getattr(a.filter, name), getattr(b.filter, name))
    for i in range(40, 60):
        out_a, out_b = a.process_sync(frame(i)), b.process_sync(frame(i))
        assert out_a.estimate == out_b.estimate and out_a.feedback == out_b.feedback
    assert checkpoint.pack(a.capture()) == checkpoint.pack(b.capture())
    m.close()


def manager(store: MemoryStore, **overrides: object) -> SessionManager:
    settings = make_settings(store_lease_s=0.3, checkpoint_interval_s=0.2, **overrides)
    return SessionManager({"paper_office": OFFICE}, settings, Metrics(), store)


SPEC = SessionSpec(map_name="paper_office", particles=3000, seed=4)


def test_a_session_moves_between_workers_and_goes_on_exactly() -> None:
    """Worker A serves 25 frames and dies without a word; B resumes the session from the
    checkpoint and the journal and takes the very step A would have taken."""

    async def main() -> None:
        store = MemoryStore(shared=True)
        a = manager(store)
        sid = (await a.create(SPEC)).id
        assert a.sessions() == []  # published, not kept: any worker may take it
        with pytest.raises(SessionNotFound):
            a.get(sid)
        keeper = asyncio.create_task(a.sharing.run_keeper())
        for i in range(25):
            await a.process(sid, frame(i))
            if i == 12:
                # Let the keeper write a checkpoint mid-walk, once converged: a lost
                # filter is checkpointed on a subsample, which no replay follows exactly
                # (on a busy machine the keeper's turn can come later than any fixed wait).
                for _ in range(200):
                    await asyncio.sleep(0.05)
                    if store._values.get(f"{sid}:ckpt:frames", (0, 0.0))[0] == 13:
                        break
                assert store._values[f"{sid}:ckpt:frames"][0] == 13
        keeper.cancel()
        # The store as A would leave it if it died now: frames 14-25 only in the journal.
        # (A goes on in the original store, to say what it would have answered.)
        after_death = MemoryStore(shared=True)
        after_death._values = {
            k: (list(v) if isinstance(v, list) else v, t) for k, (v, t) in store._values.items()
        }
        # When A's lease runs out in that store (monotonic seconds, the loop's clock).
        lease_ends = after_death._values[f"{sid}:lease"][1]
        out_a = await a.process(sid, frame(25))  # what A would have said
        b = manager(after_death)
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        out_b = await b.process(sid, frame(25))  # waits for A's lease to run out (0.3 s)
        answered = loop.time()
        assert out_b.seq == out_a.seq == 26
        # B took the session only once A's lease had run out (however long A's last frame
        # and B's start-up took on a busy machine), and did not wait much longer.
        assert answered >= lease_ends and answered - t0 < 2.0
        assert out_b.estimate == out_a.estimate and out_a.estimate.converged
        assert out_b.feedback == out_a.feedback
        assert b.metrics.sessions_resumed._value.get() == 1
        for m in (a, b):
            m.close()

    asyncio.run(main())


def test_a_stepping_session_is_checkpointed_at_least_once_an_interval() -> None:
    """docs/API.md: at least once a second (here every 0.2 s) while the session changes;
    and not far more often than that either."""

    async def main() -> None:
        store = MemoryStore(shared=True)
        a = manager(store)  # checkpoint_interval_s 0.2
        sid = (await a.create(SPEC)).id
        times: list[float] = []
        save = store.save

        async def timed_save(items: Any, owner: str, lease_s: float, ttl_s: float) -> list[bool]:
            if any(item[0] == sid for item in items):
                times.append(asyncio.get_running_loop().time())
            return await save(items, owner, lease_s, ttl_s)

        store.save = timed_save  # type: ignore[method-assign]
        keeper = asyncio.create_task(a.sharing.run_keeper())
        loop = asyncio.get_running_loop()
        end = loop.time() + 1.6
        i = 0
        while loop.time() < end:
            await a.process(sid, frame(i % 60))
            i += 1
            await asyncio.sleep(0.02)
        keeper.cancel()
        gaps = np.diff(times)
        assert len(gaps) >= 5, times
        assert gaps.max() <= 0.2, gaps  # a fixed tick left some 0.3 s apart
        assert gaps.mean() >= 0.1, gaps
        a.close()

    asyncio.run(main())


def test_a_worker_that_lost_its_lease_never_forks_the_session() -> None:
    async def main() -> None:
        store = MemoryStore(shared=True)
        a, b = manager(store), manager(store)
        sid = (await a.create(SPEC)).id
        for i in range(3):
            await a.process(sid, frame(i))
        stale = a.get(sid)
        await asyncio.sleep(0.35)  # A stalls past its lease; B takes the session on
        assert (await b.process(sid, frame(3))).seq == 4
        await asyncio.sleep(0.35)  # ... and goes quiet (its lease runs out too)
        # A's copy (3 frames) is stale: its step is refused by the store (no fork), A
        # drops the copy; sent again, the frame runs on the stored state, after B's.
        with pytest.raises(SessionUnavailable, match="another worker"):
            await a.process(sid, frame(4))
        assert sid not in {s.id for s in a.sessions()}
        out = await a.process(sid, frame(4))
        assert out.seq == 5 and a.get(sid) is not stale
        assert a.metrics.sessions_resumed._value.get() == 2
        await b.delete(sid)
        with pytest.raises(SessionNotFound):
            await b.find(sid)
        for m in (a, b):
            m.close()

    asyncio.run(main())


def test_idle_sessions_are_let_go_and_shutdown_checkpoints_everything() -> None:
    async def main() -> None:
        store = MemoryStore(shared=True)
        a, b = manager(store), manager(store)
        a.sharing.handoff_idle_s = 0.2
        sid = (await a.create(SPEC)).id
        for i in range(5):
            await a.process(sid, frame(i))
        await asyncio.sleep(0.3)
        await a.sharing.keep()
        assert a.sessions() == []  # idle: checkpointed and released
        got = await b.find(sid)
        assert got.frames == 5 and b.sessions() == [got]
        await b.process(sid, frame(5))
        await b.sharing.shutdown()
        assert b.sessions() == []
        with pytest.raises(SessionUnavailable, match="shutting down"):
            await b.find(sid)
        resumed = await a.find(sid)  # released at shutdown: no wait
        assert resumed.frames == 6
        for m in (a, b):
            m.close()

    asyncio.run(main())


def test_unknown_ids_are_not_found_through_the_store() -> None:
    async def main() -> None:
        m = manager(MemoryStore(shared=True))
        with pytest.raises(SessionNotFound):
            await m.find("no-such-session")
        with pytest.raises(SessionNotFound):
            await m.delete("no-such-session")
        m.close()

    asyncio.run(main())


def test_an_object_taken_for_moved_stays_out_of_a_session_restored_from_the_store() -> None:
    """The stale-map exclusion is session state: packed into the store's bytes and
    unpacked on another worker, the moved object is still out of the sensor model, its
    window made without it, and the session goes on the same way."""
    from tests.localization.test_filter import _standing_at_a_stale_place

    a, changed, stream = _standing_at_a_stale_place(moved=True)
    for dets in stream[:20]:
        a.step(Odometry(0.0, 0.0, 0.0), dets)
    assert a.unseen is not None and a.unseen.moved[changed]
    data = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "filter": a.checkpoint()})
    b = ParticleFilter(a.map, a.config, rng=np.random.default_rng(99))
    b.restore(checkpoint.unpack(data)["filter"])
    assert b.unseen is not None and np.array_equal(b.unseen.moved, a.unseen.moved)
    assert b.sensor.excluded == a.sensor.excluded == (changed,)  # type: ignore[attr-defined]
    assert b.evidence is not None and a.evidence is not None
    assert all(changed not in obs.members.tolist() for _, obs, _ in b.evidence._history)
    for dets in stream[20:]:
        still = Odometry(0.0, 0.0, 0.0)
        ea, eb = a.step(still, dets), b.step(still, dets)
        assert math.hypot(ea.x - eb.x, ea.y - eb.y) < 1e-3
        assert ea.converged == eb.converged


def test_a_narrow_cameras_filter_comes_back_with_both_edges_and_its_exclusions() -> None:
    """Through a 66-degree camera the filter weighs with the field of view's soft edge
    and its evidence tracker with the hard one (models.FOV_EDGE_STDS): packed into the
    store's bytes and unpacked on another worker, both models come back, an object taken
    for moved is out of both, and the walk goes on the same way."""
    config = FilterConfig(particles=CHECKPOINT_PARTICLES, fov_deg=66.0)
    walk = simulate(OFFICE, paper_config("nominal", 66.0), np.random.default_rng(5))
    a = ParticleFilter(OFFICE, config, rng=np.random.default_rng(3))
    for f in walk[:40]:
        a.step(f.odometry, f.detections)
    assert a.unseen is not None and a.n <= CHECKPOINT_PARTICLES
    a.unseen.moved[1] = True
    a._exclude_moved()
    data = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "filter": a.checkpoint()})
    b = ParticleFilter(OFFICE, config, rng=np.random.default_rng(99))
    b.restore(checkpoint.unpack(data)["filter"])
    assert b.evidence is not None and b.evidence.sensor is not b.sensor
    assert b.sensor.fov_margin_deg > 0.0 == b.evidence.sensor.fov_margin_deg  # type: ignore[attr-defined]
    assert b.sensor.excluded == b.evidence.sensor.excluded == (1,)  # type: ignore[attr-defined]
    for f in walk[40:60]:
        ea, eb = a.step(f.odometry, f.detections), b.step(f.odometry, f.detections)
        assert math.hypot(ea.x - eb.x, ea.y - eb.y) < 1e-3
        assert ea.converged == eb.converged


def test_a_restored_session_keeps_its_count_of_slow_frames() -> None:
    """Two frames 200 s apart before the capture, one after the restore: the third in a
    row is warned about on the restored session as on the original."""
    m = manager(MemoryStore(shared=True))
    a = m.build(SPEC)
    for ts in (1000.0, 1200.0, 1400.0):
        a.process_sync(FrameInput(timestamp=ts, odometry=Odometry(0.1, 0.0, 0.0)))
    assert a.slow_frames == 2
    state = checkpoint.unpack(checkpoint.pack(a.capture()))
    b = rebuild(m, state)
    assert b.slow_frames == 2
    nxt = FrameInput(timestamp=1600.0, odometry=Odometry(0.1, 0.0, 0.0))
    out_a, out_b = a.process_sync(nxt), b.process_sync(nxt)
    assert out_a.warnings == out_b.warnings
    assert any(w.startswith("timestamps 200 s apart, 3 frames") for w in out_b.warnings)
    older = {k: v for k, v in state.items() if k != "slow_frames"}  # before it was kept
    assert rebuild(m, older).slow_frames == 0
    m.close()
