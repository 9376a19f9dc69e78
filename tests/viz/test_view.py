"""The viser scene and the live view, with viser's own server and no browser."""

from __future__ import annotations

import asyncio
import functools
import time

import numpy as np
import pytest
import viser

from app.demo import frame_input_of, new_walk
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.types import FrameInput, SessionSpec
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate
from app.viz.particles import MAX_DRAWN, detection_rays, sample_particles
from app.viz.scene import build_map_scene, top_down_camera
from app.viz.view import LiveView
from tests.helpers import free_port, make_manager, make_settings, paper_office

OFFICE = paper_office()


@pytest.fixture
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield srv
    srv.stop()


def test_scene_has_the_map(server: viser.ViserServer) -> None:
    scene = build_map_scene(server, OFFICE)
    assert scene.walls is not None
    assert scene.walls.points.shape == (4, 2, 3)
    assert sorted(h.points.shape[0] for h in scene.objects) == [1, 4, 6]
    assert all(h.points.dtype == np.float32 for h in scene.objects)  # float32, not float16
    assert len(scene.labels) == 11 + 1  # every object, and the one region
    assert any(label.text == "main entrance" for label in scene.labels)


def test_camera_frames_the_whole_map(server: viser.ViserServer) -> None:
    build_map_scene(server, OFFICE)
    pos = np.asarray(server.initial_camera.position)
    look = np.asarray(server.initial_camera.look_at)
    assert look[:2] == pytest.approx((5.0, 3.5))
    # Looking (almost) straight down from high enough that a 75 deg view spans the map.
    assert pos[2] > 0 and np.hypot(*(pos[:2] - look[:2])) < 0.1 * pos[2]
    half_width = pos[2] * np.tan(np.radians(75 / 2))
    assert half_width >= 5.0
    assert top_down_camera(OFFICE)[0][2] == pytest.approx(pos[2])


def test_particles_are_sampled_by_weight_and_capped() -> None:
    async def main():
        manager = make_manager()
        s = await manager.create(SessionSpec(map_name="paper_office", particles=8000, seed=1))
        frames = simulate(OFFICE, paper_config("nominal", 360), np.random.default_rng(1))[:3]
        for f in frames:
            await manager.process(s.id, frame_input_of(f))
        return s.snapshot()

    snap = asyncio.run(main())
    pts, colours, ticks = sample_particles(snap, np.random.default_rng(0))
    assert pts.shape == (MAX_DRAWN, 3) and colours.shape == (MAX_DRAWN, 3)
    assert ticks.shape == (MAX_DRAWN, 2, 3)
    assert detection_rays(snap).shape == (11, 2, 3)
    # Drawn particles concentrate where the weight is: near the estimate.
    est = snap.estimate
    assert np.median(np.hypot(pts[:, 0] - est.x, pts[:, 1] - est.y)) < 1.0


def test_live_view_draws_the_watched_session() -> None:
    async def main() -> LiveView:
        manager = make_manager()
        view = LiveView(
            manager,
            port=free_port(),
            host="127.0.0.1",
            start_walk=functools.partial(new_walk, manager),
        )
        view.start()
        try:
            s = await manager.create(
                SessionSpec(map_name="paper_office", particles=2000, seed=2, share_view=True)
            )
            frames = simulate(OFFICE, paper_config("nominal", 360), np.random.default_rng(2))[:5]
            for f in frames:
                await manager.process(s.id, frame_input_of(f))
            deadline = time.time() + 10
            while view._last_version != s.version and time.time() < deadline:
                await asyncio.sleep(0.05)
            assert view.watched == s.id  # the newest session is watched by default
            assert view.controls is not None
            assert s.id not in view.controls.session.options  # a label, never the id
            assert view.controls.label(s) in view.controls.session.options
            assert view.refresh() is False  # nothing new: nothing redrawn
            await manager.process(s.id, FrameInput())
            assert view.refresh() is True
            # The GUI's demo button starts a simulated walk and watches it.
            sid = await view.controls.start_walk()
            assert view.watched == sid
            deadline = time.time() + 10  # the walk simulates its path, then 5 frames/s
            while manager.get(sid).frames < 2 and time.time() < deadline:
                await asyncio.sleep(0.05)
            assert manager.get(sid).frames >= 2
            await view.controls.reset_walk()
            return view
        finally:
            view.stop()

    view = asyncio.run(main())
    assert view.frames_drawn >= 1


def test_the_view_draws_the_way_to_the_destination() -> None:
    from app.guidance import DestinationSpec

    async def main():
        manager = make_manager()
        view = LiveView(manager, port=free_port(), host="127.0.0.1")
        view.start()
        try:
            from app.localization.types import InitialPose

            s = await manager.create(
                SessionSpec(
                    map_name="paper_office",
                    particles=2000,
                    seed=3,
                    initial_pose=InitialPose(1.5, 1.2, 0.0, 0.3, 0.2),
                )
            )
            await manager.set_destination(s.id, DestinationSpec("label", "main entrance"))
            frames = simulate(OFFICE, paper_config("nominal", 360), np.random.default_rng(3))
            for f in frames[:15]:
                await manager.process(s.id, frame_input_of(f))
            snap = s.snapshot()
            with view._draw_lock:  # the view's own thread may be drawing too
                view.draw(snap)
                return snap, view.route
        finally:
            view.stop()

    snap, route = asyncio.run(main())
    assert snap.route is not None and route is not None and route.visible
    assert route.points.shape == (len(snap.route) - 1, 2, 3)
    # From the estimate to the door at (10, 5.5).
    assert route.points[-1, 1, :2] == pytest.approx((10.0, 5.5))
    assert route.points[0, 0, :2] == pytest.approx((snap.estimate.x, snap.estimate.y), abs=1e-4)


def test_a_venue_is_shown_one_level_at_a_time_the_persons_or_the_chosen_one() -> None:
    from app.simulation.simulator import SimulationConfig
    from app.simulation.venue import VENUE_NAME, venue_legs, venue_map
    from app.simulation.venue_walk import simulate_venue

    venue = venue_map()
    manager = SessionManager({VENUE_NAME: venue}, make_settings(), Metrics())
    view = LiveView(manager, port=free_port(), max_rate_hz=50)

    async def main() -> None:
        view.start()
        try:
            assert view.controls is not None
            names = ("Ground Floor", "First Floor", "Second Floor")
            assert tuple(view.controls.level.options) == ("(the person's level)", *names)
            scene = view.map_scene
            assert scene is not None and scene.level_groups is not None
            assert [g.visible for g in scene.level_groups] == [True, False, False]
            s = await manager.create(
                SessionSpec(map_name=VENUE_NAME, particles=3000, seed=2, share_view=True)
            )
            start, legs = venue_legs()
            cfg = SimulationConfig(path=((0.0, 0.0),))
            frames = simulate_venue(venue, start, legs[:3], cfg, np.random.default_rng(2))
            for vf in frames:
                f = vf.frame
                await manager.process(
                    s.id,
                    FrameInput(
                        odometry=f.odometry, detections=tuple(f.detections), altitude=vf.altitude
                    ),
                )
            assert s.last_outcome is not None and s.last_outcome.level is not None
            assert s.last_outcome.level.id == "L2"
            view.watch(s.id)
            view.refresh()  # (the view's own thread may have drawn it first)
            # The person's level: the Second Floor alone, framed from above.
            assert [g.visible for g in scene.level_groups] == [False, False, True]
            look = np.asarray(view.server.initial_camera.look_at)  # type: ignore[union-attr]
            assert look[0] == pytest.approx(12.0 + 2 * venue.layout.pitch_m)
            # A level chosen in the panel is shown whatever the person's.
            view.choose_level("Ground Floor")
            view.refresh()
            assert [g.visible for g in scene.level_groups] == [True, False, False]
            # Back to following the person: the Second Floor again.
            view.choose_level("(the person's level)")
            view.refresh()
            assert [g.visible for g in scene.level_groups] == [False, False, True]
        finally:
            view.stop()
            manager.close()

    asyncio.run(main())
