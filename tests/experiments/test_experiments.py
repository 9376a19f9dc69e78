"""The experiments command end to end (small), and its pieces."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from app.experiments import cli
from app.experiments.figures import single_frame_crlb_m
from app.experiments.protocol import PAPER_RESULTS, cells
from app.localization.types import Pose
from app.maps.model import parse_map

ROW_KEYS = {
    "table", "scenario", "fov_deg", "config", "mean_m", "std_m", "mean_deg", "std_deg",
    "final_third_mean_m", "worst_seed_mean_m", "seeds",
}  # fmt: skip


def test_protocol_covers_every_cell() -> None:
    todo = cells(("I", "II", "III"))
    assert len(todo) == 3 * 3 * 3  # paper, bearings, bearings with a fixed particle count
    assert {(c.table, c.fov_deg) for c in todo} == set(PAPER_RESULTS)
    assert len(cells(("IV",))) == 2 * 4 * 3 * 2
    with pytest.raises(ValueError, match="unknown table"):
        cells(("V",))


def test_small_end_to_end_run(tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(
        [
            "--tables",
            "I",
            "--seeds",
            "1",
            "--particles",
            "600",
            "--workers",
            "1",
            "--out",
            str(tmp_path),
        ]
    )
    assert cli.run(args) == 0
    rows = json.loads((tmp_path / "tables.json").read_text())
    assert len(rows) == 9
    for row in rows:
        assert set(row) >= ROW_KEYS
        assert row["table"] == "I" and row["scenario"] == "nominal" and row["seeds"] == 1
        assert 0 <= row["mean_m"] < 5 and row["worst_seed_mean_m"] >= row["mean_m"] - 1e-12
    md = (tmp_path / "tables.md").read_text()
    assert "0.033" in md  # the paper's published 360 deg figure stands beside ours
    assert "degrees" in md
    assert "## Adaptive particle count" in md and md.count("| I | ") == 3
    for name in ("fig5_trajectories_tableI.png", "fig6_errors_tableI.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_crlb_matches_a_hand_computed_case() -> None:
    # Four objects at distance 2 in the four axis directions, sigma = 1 deg.
    m = parse_map(
        {"name": "cross", "objects": [
            {"class": "a", "x": 2, "y": 0}, {"class": "a", "x": -2, "y": 0},
            {"class": "a", "x": 0, "y": 2}, {"class": "a", "x": 0, "y": -2}]}
    )  # fmt: skip
    # Each bearing gradient has magnitude 1/r = 0.5 along one axis, two per axis:
    # information per axis 2 * 0.25 / s^2, the heading column is orthogonal to them
    # by symmetry, so var(x) = var(y) = s^2 / 0.5 and the bound is sqrt(2 * 2 s^2).
    s = np.radians(1.0)
    assert single_frame_crlb_m(m, Pose(0, 0, 0), 360, 1.0) == pytest.approx(
        np.sqrt(4 * s * s / 1.0)
    )


def test_pcrb_single_step_by_hand() -> None:
    """One step of the Tichavsky recursion against the closed form, numbers by hand.

    Prior information J0 = diag(100, 100, 400), no motion (F = I), process noise
    Q = diag(0.01, 0.01, 0.0025): the prior after the noise is 1 / (1/J0 + Q) per axis,
    i.e. 1 / (0.01 + 0.01) = 50 for x and y and 1 / (0.0025 + 0.0025) = 200 for theta.
    One object 2 m ahead on +x, bearing noise 0.1 rad: its gradient is (0, -1/2, -1),
    so it adds (0, 0.25, 0.5; ., 1) / 0.01 to the (y, theta) block.
    """
    from app.experiments.pcrb import pcrb_step

    j0 = np.diag([100.0, 100.0, 400.0])
    q = np.diag([0.01, 0.01, 0.0025])
    h = np.array([[0.0, -0.5, -1.0]])
    j1 = pcrb_step(j0, np.eye(3), q, h, 0.01)
    expected = np.array([[50.0, 0.0, 0.0], [0.0, 75.0, 50.0], [0.0, 50.0, 300.0]])
    assert np.allclose(j1, expected, rtol=1e-12, atol=1e-9)


def test_pcrb_on_the_paper_walk_is_below_the_single_frame_bound() -> None:
    """Odometry only adds information: the PCRB lies under one frame's bound."""
    from app.experiments.pcrb import pcrb_position_m
    from app.maps.check import load_map
    from app.resources import bundled_maps_dir
    from app.simulation.scenarios import paper_config
    from app.simulation.simulator import simulate

    paper_office = load_map(bundled_maps_dir() / "paper_office.json")
    frames = simulate(paper_office, paper_config("nominal", 360), np.random.default_rng(0))
    truth = [f.truth for f in frames]
    bound = pcrb_position_m(paper_office, truth, 360.0, 2.0, 0.02, 1.0)
    single = np.array([single_frame_crlb_m(paper_office, p, 360.0, 2.0) for p in truth])
    assert bound[0] == pytest.approx(single[0], rel=1e-6)
    assert np.all(bound[1:] <= single[1:] * (1 + 1e-9))
    assert 0.0 < bound[-1] < bound[0]


def test_building_suite_walks_both_wings_and_recovers_from_the_kidnap(tmp_path) -> None:
    from app.experiments import building
    from app.experiments.building import first_right_fix_s

    runs = [building.run_condition(c, 0, 3000) for c in ("nominal-360", "kidnap-360")]
    for r in runs:
        # The walk reaches the east wing, and the filter follows it there.
        assert r.truth_xy[:, 0].max() > 30.0 and r.truth_xy[:, 0].min() < 5.0
        assert np.isfinite(first_right_fix_s(r))
        assert r.err_m[-25:].max() < 0.5
    kidnap = runs[1]
    jumped = np.hypot(*np.diff(kidnap.truth_xy, axis=0).T).max()
    assert jumped > 15.0  # carried from the east corridor to the west one
    rows = building.summarize(runs)
    assert [r["condition"] for r in rows] == ["nominal-360", "kidnap-360"]
    assert np.isfinite(rows[1]["median_recovery_s"])
    text = building.markdown(rows, seconds=1.0, particles=3000, seeds=1)
    assert "| kidnap-360 |" in text
    assert building.figure(runs, tmp_path).is_file()
