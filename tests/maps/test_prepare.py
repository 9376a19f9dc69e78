"""Map preparation: the compiled grids equal brute-force references; the disk cache."""

from __future__ import annotations

import numpy as np
import pytest

from app.maps.check import load_map
from app.maps.geometry import point_segment_distance, segments_cross_walls
from app.maps.model import WALL_CLEARANCE_M, MapNotPrepared, SemanticMap, parse_map
from app.maps.prepare import (
    build,
    build_free_space,
    content_key,
    ensure_prepared,
    grid_frame,
    prepare,
)
from app.resources import bundled_maps_dir


def random_floor(seed: int) -> SemanticMap:
    """A walled 9 m x 6 m box with random inner walls (some diagonal) and objects."""
    rng = np.random.default_rng(seed)
    walls = [
        {"x1": 0, "y1": 0, "x2": 9, "y2": 0},
        {"x1": 9, "y1": 0, "x2": 9, "y2": 6},
        {"x1": 9, "y1": 6, "x2": 0, "y2": 6},
        {"x1": 0, "y1": 6, "x2": 0, "y2": 0},
    ]
    for _ in range(8):
        x, y = rng.uniform(0.5, 8.5), rng.uniform(0.5, 5.5)
        a, length = rng.uniform(0, np.pi), rng.uniform(0.5, 3.0)
        walls.append({"x1": x, "y1": y, "x2": x + length * np.cos(a), "y2": y + length * np.sin(a)})
    objects = [
        {"class": "table", "x": float(rng.uniform(0.3, 8.7)), "y": float(rng.uniform(0.3, 5.7))}
        for _ in range(12)
    ]
    objects.append({"class": "door", "x": 9.0, "y": 3.0})  # mounted in the east wall
    return parse_map({"name": f"random{seed}", "walls": walls, "objects": objects})


def reference_free_mask(m: SemanticMap) -> np.ndarray:
    """The definition, brute force: axis rays hit a wall on all four sides, and clear."""
    ox, oy, res, rows, cols = grid_frame(m.bounds, True, None)
    gx, gy = np.meshgrid(ox + (np.arange(cols) + 0.5) * res, oy + (np.arange(rows) + 0.5) * res)
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    mask = np.ones(centres.shape[0], dtype=bool)
    for d in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        mask &= segments_cross_walls(centres, centres + 100.0 * np.array(d), m.walls)
    clear = point_segment_distance(centres, m.walls).min(axis=1)
    mask &= clear >= WALL_CLEARANCE_M + res * np.sqrt(0.5)
    return mask.reshape(rows, cols)


def test_free_space_equals_the_brute_force_definition() -> None:
    for seed in range(4):
        m = random_floor(seed)
        got = build(m).free_space.mask
        want = reference_free_mask(m)
        assert got.shape == want.shape
        # Cells whose centre lies within float rounding of a boundary may differ.
        assert np.count_nonzero(got != want) <= 2, seed


def test_visibility_equals_line_of_sight_at_cell_centres() -> None:
    for seed in range(4):
        m = random_floor(seed)
        vis = build(m).visibility
        cols = vis.shape[1]
        used = np.flatnonzero(vis.table.any(axis=1))
        r, c = np.divmod(used, cols)
        centres = np.column_stack(
            [
                vis.origin_x + (c + 0.5) * vis.resolution_m,
                vis.origin_y + (r + 0.5) * vis.resolution_m,
            ]
        )
        assert np.array_equal(vis.table[used], m.line_of_sight(centres)), seed
        # Rows read straight from the packed bits equal the unpacked table's.
        assert np.array_equal(vis.visible(centres[:, 0], centres[:, 1]), vis.table[used])
        assert used.size > 100, seed  # the test saw many cells


def test_cache_round_trip_and_key(tmp_path) -> None:
    m = load_map(bundled_maps_dir() / "paper_office.json")
    first = prepare(m, tmp_path)
    assert not first.from_cache
    assert len(list(tmp_path.glob("*.npz"))) == 1
    again = load_map(bundled_maps_dir() / "paper_office.json")
    second = prepare(again, tmp_path)
    assert second.from_cache
    assert np.array_equal(second.free_space.mask, first.free_space.mask)
    assert np.array_equal(second.visibility.bits, first.visibility.bits)
    assert np.array_equal(second.visibility.table, first.visibility.table)
    assert second.visibility.shape == first.visibility.shape
    # Another map (one object moved) has another key.
    data = m.to_json()
    data["objects"][0]["x"] += 0.5
    assert content_key(parse_map(data)) != content_key(m)


def test_a_corrupt_cache_file_is_rebuilt(tmp_path) -> None:
    m = load_map(bundled_maps_dir() / "paper_office.json")
    prepare(m, tmp_path)
    (path,) = tmp_path.glob("*.npz")
    path.write_bytes(b"not a numpy file")
    again = prepare(load_map(bundled_maps_dir() / "paper_office.json"), tmp_path)
    assert not again.from_cache
    assert np.array_equal(again.free_space.mask, m.free_space.mask)


def test_preparing_is_an_explicit_step() -> None:
    """Reading a grid builds nothing: an unprepared map says what to call; the loader and
    ensure_prepared prepare (once: a second call keeps the same grids)."""
    m = random_floor(5)
    assert not m.prepared
    with pytest.raises(MapNotPrepared, match=r"random5.*ensure_prepared"):
        _ = m.free_space
    with pytest.raises(MapNotPrepared, match="visibility"):
        _ = m.visibility
    assert ensure_prepared(m) is m and m.prepared
    grid = m.visibility
    ensure_prepared(m)
    assert m.visibility is grid
    assert load_map(bundled_maps_dir() / "paper_office.json").prepared


def test_grids_of_another_map_are_refused() -> None:
    small, other = (
        random_floor(6),
        parse_map({"name": "one", "objects": [{"class": "door", "x": 1.0, "y": 1.0}]}),
    )
    got = build(small)
    with pytest.raises(ValueError, match="13 objects does not fit a map of 1"):
        other.attach(got.free_space, got.visibility)


def test_each_floor_of_a_venue_gets_a_floor_s_cells_so_a_narrow_door_stays_open() -> None:
    """Six floors of 60 x 80 m laid side by side, each with a small room behind a
    0.7 m door. One budget of cells for the whole plane made them 0.39 m wide, whose
    clearance (0.1 m plus half a cell's diagonal) from both jambs no cell centre in the
    doorway has: the room was closed to the particles (a real building's lift cars
    were). With a floor's cells per level the doorway is free space."""
    ids = [f"L{k}" for k in range(6)]
    walls = []
    objects = []
    for lv in ids:
        box = [(0, 0, 60, 0), (60, 0, 60, 80), (60, 80, 0, 80), (0, 80, 0, 0)]
        room = [(10, 10, 12, 10), (12, 10, 12, 12.5), (10, 12.5, 10, 10)]
        room += [(10, 12.5, 10.65, 12.5), (11.35, 12.5, 12, 12.5)]  # the door: 10.65-11.35
        walls += [{"x1": a, "y1": b, "x2": c, "y2": d, "level": lv} for a, b, c, d in box + room]
        objects += [{"class": "door", "x": 11.0, "y": 12.5, "level": lv}]
        objects += [{"class": "plant", "x": 30.0, "y": 40.0, "level": lv}]
    m = parse_map(
        {
            "name": "six_floors",
            "levels": [{"id": lv, "name": lv, "ordinal": k} for k, lv in enumerate(ids)],
            "walls": walls,
            "objects": objects,
        }
    )
    fs = build_free_space(m)
    assert fs.resolution_m < 0.2
    ys = np.linspace(12.3, 12.7, 9)
    for k in range(6):
        xs = np.linspace(10.65, 11.35, 15) + float(m.layout.offsets(k))
        gx, gy = np.meshgrid(xs, ys)
        assert fs.is_free(gx.ravel(), gy.ravel()).any(), f"the door of level L{k} is closed"
