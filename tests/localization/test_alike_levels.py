"""Floors drawn the same (app.maps.symmetry.alike_levels): the same place on each sees
the same, so from a global start nothing is told, and the service says why instead of
asking for a turn or a walk that cannot help."""

from __future__ import annotations

import copy
import itertools
import json
import math
from pathlib import Path

import httpx
import numpy as np

from app.localization.config import FilterConfig
from app.localization.estimate import only_alike_levels
from app.localization.filter import ParticleFilter
from app.localization.types import Estimate, Hypothesis, InitialPose
from app.main import create_app
from app.maps.check import check_data
from app.maps.model import parse_map
from app.maps.prepare import ensure_prepared
from app.maps.symmetry import alike_levels
from app.simulation.simulator import SimulationConfig
from app.simulation.venue import venue_legs, venue_map, venue_spec
from app.simulation.venue_walk import simulate_venue
from tests.helpers import free_port, make_settings, serving, venue_frame_json

NAME = "alike_floors"


def alike_spec() -> dict[str, object]:
    """The suite's venue with every floor drawn as its Ground Floor (walls and objects;
    the connectors as they are)."""
    spec = venue_spec(NAME)
    for key in ("walls", "objects"):
        ground = [item for item in spec[key] if item["level"] == "L0"]  # type: ignore[attr-defined]
        spec[key] = [{**item, "level": lv} for lv in ("L0", "L1", "L2") for item in ground]
    return spec


def test_floors_drawn_the_same_are_found_and_one_object_tells_a_floor_apart() -> None:
    assert alike_levels(parse_map(alike_spec())) == ((0, 1, 2),)
    spec = copy.deepcopy(alike_spec())
    spec["objects"].append({"class": "sign", "x": 3.0, "y": 3.0, "level": "L2"})  # type: ignore[attr-defined]
    assert alike_levels(parse_map(spec)) == ((0, 1),)
    moved = copy.deepcopy(alike_spec())
    moved["walls"][-1]["x1"] += 0.5  # type: ignore[index]
    assert alike_levels(parse_map(moved)) == ((0, 1),)
    assert alike_levels(venue_map()) == ()


def test_map_check_warns_of_floors_that_look_the_same() -> None:
    result = check_data(alike_spec(), source="alike.json")
    assert result.map is not None and not result.errors
    warned = [p for p in result.problems if p.field == "levels"]
    assert len(warned) == 1 and "'L0', 'L1', 'L2' look the same" in warned[0].message
    assert not [p for p in check_data(venue_spec()).problems if p.field == "levels"]


def _est(*modes: tuple[float, float, float, float, float]) -> Estimate:
    hyps = tuple(Hypothesis(x, y, th, w, s) for x, y, th, w, s in modes)
    return Estimate(hyps[0].x, hyps[0].y, hyps[0].theta_rad, 0.1, 0.1, 0.05, False, hyps)


def test_the_belief_is_undecided_only_when_it_is_one_place_on_alike_floors() -> None:
    layout = parse_map(alike_spec()).layout
    pitch = layout.pitch_m
    groups = ((0, 1, 2),)
    same = _est((5.0, 4.0, 0.3, 0.5, 0.2), (pitch + 5.2, 4.1, 0.35, 0.45, 0.2))
    assert only_alike_levels(same, groups, layout)
    assert not only_alike_levels(same, ((1, 2),), layout)  # level 0 not alike
    assert not only_alike_levels(same, (), layout)
    elsewhere = _est((5.0, 4.0, 0.3, 0.5, 0.2), (pitch + 8.0, 4.0, 0.3, 0.45, 0.2))
    assert not only_alike_levels(elsewhere, groups, layout)
    one_floor = _est((5.0, 4.0, 0.3, 1.0, 0.2))
    assert not only_alike_levels(one_floor, groups, layout)
    wide = _est((5.0, 4.0, 0.3, 0.5, 2.0), (pitch + 5.0, 4.0, 0.3, 0.45, 2.0))
    assert not only_alike_levels(wide, groups, layout)


def _walk(m, seed: int, frames: int):
    start, legs = venue_legs()
    config = SimulationConfig(path=((0.0, 0.0),))
    return simulate_venue(m, start, legs[:1], config, np.random.default_rng(seed))[:frames]


def _run(m, frames, start: InitialPose | None = None):
    """Each frame's truth, the filter's estimate and whether it called the floor
    undecided, through a fresh 5,000-particle filter."""
    pf = ParticleFilter(
        m, FilterConfig(particles=5000), rng=np.random.default_rng(4), initial_pose=start
    )
    for i, vf in enumerate(frames):
        f = vf.frame
        est = pf.step(None if i == 0 else f.odometry, f.detections, altitude=vf.altitude)
        yield f.truth, est, pf.levels_undecided


def test_on_alike_floors_nothing_is_told_and_the_filter_says_the_floor_is_undecided() -> None:
    m = ensure_prepared(parse_map(alike_spec()))
    steps = list(_run(m, _walk(m, 3, 120)))
    assert not any(est.converged for _, est, _ in steps)
    assert np.mean([undecided for *_, undecided in steps[-60:]]) >= 0.9
    # A start on a floor (initial_pose on the Ground Floor) tells it: located, there.
    frames = _walk(m, 3, 60)
    p = frames[0].frame.truth
    steps = list(_run(m, frames, InitialPose(p.x, p.y, p.theta_rad, 0.3, 0.2)))
    assert not any(undecided for *_, undecided in steps)
    told = [est for _, est, _ in steps if est.converged]
    assert len(told) >= 0.8 * len(steps)
    assert all(math.hypot(e.x - t.x, e.y - t.y) < 1.0 for t, e, _ in steps if e.converged)
    # The same walk on the venue whose floors differ: located, never undecided.
    real = venue_map()
    steps = list(_run(real, _walk(real, 3, 120)))
    assert not any(undecided for *_, undecided in steps)
    assert any(est.converged for _, est, _ in steps)


def test_the_service_says_the_floors_look_the_same_instead_of_a_suggestion(
    tmp_path: Path,
) -> None:
    (tmp_path / f"{NAME}.json").write_text(json.dumps(alike_spec()))
    m = ensure_prepared(parse_map(alike_spec()))
    frames = _walk(m, 5, 90)
    app = create_app(make_settings(maps=[tmp_path], max_particles=5000))
    with serving(app, free_port()) as host, httpx.Client(base_url=f"http://{host}") as http:
        sid = http.post("/sessions", json={"map": NAME, "seed": 2}).json()["id"]
        results = []
        for vf in frames:
            r = http.post(f"/sessions/{sid}/frames", json=venue_frame_json(vf))
            assert r.status_code == 200, r.text
            results.append(r.json())
    assert not any(res["converged"] for res in results)
    assert results[-1]["feedback"]["suggestion"] is None
    said = [k for k, res in enumerate(results) if "floors look the same" in res["feedback"]["text"]]
    assert said and all(b - a >= 50 for a, b in itertools.pairwise(said))  # 10 s at 5 frames/s
    assert not any("Walk a few steps" in res["feedback"]["text"] for res in results[said[0] :])
    levels = {json.dumps(h["level"], sort_keys=True) for h in results[-1]["hypotheses"]}
    assert len(levels) >= 2
