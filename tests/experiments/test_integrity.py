"""The integrity suite: a tiny run end to end, the metrics by hand, and (slow) the
whole suite against the issue's figures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from app.experiments import cli
from app.experiments.hard_maps import BUILDERS, hard_map
from app.experiments.integrity import (
    QUICK,
    IntegrityRun,
    Scenario,
    first_fix_s,
    flips,
    metrics,
    run_scenario,
    scenarios,
)
from app.maps.prepare import ensure_prepared


def fake(err: list[float], conv: list[bool], prot: list[float] | None = None) -> IntegrityRun:
    n = len(err)
    p = np.full(n, np.nan) if prot is None else np.array(prot)
    return IntegrityRun(
        Scenario("paper_office", "nominal-360"), 0, np.arange(n) * 0.2, np.array(err),
        np.array(conv), p, np.zeros(n),
    )  # fmt: skip


def test_metrics_by_hand() -> None:
    r = fake(
        [3.0, 2.0, 0.1, 0.1, 0.2, 0.1, 1.5, 0.1],
        [False, True, True, False, True, True, True, False],
        [np.nan, 5.0, 0.5, np.nan, 0.1, 0.5, 0.5, np.nan],
    )
    assert flips(r) == 2  # lost at frame 3 (0.1 m) and frame 7 (0.1 m)
    assert first_fix_s(r) == pytest.approx(0.2)
    m = metrics([r])
    assert m["wrong_frames"] == 2  # frames 1 and 6: converged, more than 1 m off
    right = [2, 3, 4, 5, 7]
    assert m["availability"] == pytest.approx(3 / len(right))
    assert m["coverage"] == pytest.approx(3 / 5)  # frames 1, 2, 5 covered of 1, 2, 4, 5, 6


def test_every_map_has_free_start_and_kidnap_poses() -> None:
    for name in BUILDERS:
        hm = hard_map(name)
        fs = ensure_prepared(hm.map).free_space
        xs = [p[0] for p in hm.path] + [hm.kidnap_pose[0]]
        ys = [p[1] for p in hm.path] + [hm.kidnap_pose[1]]
        assert fs.is_free(np.array(xs), np.array(ys)).all(), name
    assert len(scenarios()) >= 6 * 6
    assert {s.fov_deg for s in scenarios()} == {90.0, 180.0, 270.0, 360.0}


def test_rotation_room_has_its_symmetry() -> None:
    m = hard_map("rotation_room").map
    xy = {(round(x, 6), round(y, 6), m.class_of(i)) for i, (x, y) in enumerate(m.object_xy)}
    image = {(round(12 - x, 6), round(8 - y, 6), c) for x, y, c in xy}
    assert xy - image == {(12.0, 6.0, "door")}


def test_tiny_suite_end_to_end(tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(
        ["--suite", "integrity", "--quick", "--seeds", "1", "--particles", "2000",
         "--workers", "1", "--out", str(tmp_path)]
    )  # fmt: skip
    assert cli.run(args) == 0
    summary = json.loads((tmp_path / "integrity.json").read_text())
    assert len(summary["scenarios"]) == len(QUICK)
    assert summary["total"]["frames"] > 1200
    assert (tmp_path / "integrity.png").stat().st_size > 10_000
    assert "| rotation_room | nominal-180 |" in (tmp_path / "integrity.md").read_text()


def test_one_run_is_reproducible() -> None:
    s = Scenario("mirror_room", "nominal-360")
    a = run_scenario(s, 4, 1500)
    b = run_scenario(s, 4, 1500)
    assert np.array_equal(a.err_m, b.err_m) and np.array_equal(a.converged, b.converged)


@pytest.mark.slow
def test_full_suite_meets_the_issue(tmp_path: Path) -> None:
    """Issue 12's done-when figures over the whole suite (10 seeds, several minutes)."""
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(["--suite", "integrity", "--workers", "2", "--out", str(tmp_path)])
    assert cli.run(args) == 0
    summary = json.loads((tmp_path / "integrity.json").read_text())
    total = summary["total"]
    assert total["wrong_share"] <= 0.001
    assert total["coverage"] >= 0.99
    rows = {(r["map"], r["condition"]): r for r in summary["scenarios"]}
    assert all(r["flips_per_min"] <= 1.0 for r in rows.values())
    assert rows[("paper_office", "nominal-360")]["availability"] >= 0.9
    assert rows[("paper_office", "nominal-180")]["availability"] >= 0.7
    assert rows[("paper_office", "nominal-360")]["median_first_fix_s"] <= 3.0
