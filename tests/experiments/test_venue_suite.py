"""The venue suite's availability figures (app/experiments/venue.py): like with like."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from app.experiments.venue import (
    CONDITIONS,
    _availability,
    _walk,
    filter_config,
    leg_availability,
    markdown,
)
from app.localization.config import FilterConfig
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.types import SensorSpec, SessionSpec
from app.simulation.venue import VENUE_NAME, venue_map
from tests.helpers import make_settings


def test_located_frames_start_at_the_later_first_fix_for_both_filters() -> None:
    t = np.arange(10) * 0.2
    venue = np.array([0, 0, 0, 0, 1, 1, 1, 0, 1, 1], dtype=bool)
    one = np.array([0, 1, 1, 1, 1, 1, 1, 1, 1, 0], dtype=bool)
    leg = leg_availability(0, t, venue, one, global_start=True)
    assert (leg.venue_right, leg.one_right, leg.frames) == (5, 8, 10)
    assert np.isclose(leg.venue_first_fix_s, 0.8) and np.isclose(leg.one_first_fix_s, 0.2)
    # Frames 4..9 for both: the venue misses frame 7, the one-level map frame 9.
    assert (leg.located_frames, leg.venue_right_located, leg.one_right_located) == (6, 5, 5)


def test_a_leg_one_filter_never_fixes_has_no_located_frames() -> None:
    t = np.arange(4) * 0.2
    leg = leg_availability(1, t, np.zeros(4, bool), np.ones(4, bool), global_start=False)
    assert leg.venue_first_fix_s == float("inf") and leg.located_frames == 0
    a = _availability([leg])
    assert a["frames"] == 4 and a["one_level"] == 1.0 and a["venue"] == 0.0
    assert np.isnan(a["venue_located"])  # no frame to judge, not a perfect score
    assert a["one_level_global"] == 1.0  # without a second filter, the one-level's own


def test_a_leg_after_a_ride_counts_the_one_level_map_started_with_no_knowledge() -> None:
    t = np.arange(4) * 0.2
    known = np.ones(4, bool)
    unknown = np.array([0, 0, 1, 1], dtype=bool)
    leg = leg_availability(1, t, known, known, global_start=False, one_global_right=unknown)
    assert (leg.one_right, leg.one_global_right) == (4, 2)
    a = _availability([leg])
    assert a["one_level"] == 1.0 and a["one_level_global"] == 0.5


def test_the_phone_condition_filters_as_a_service_session_with_vio_odometry() -> None:
    manager = SessionManager({VENUE_NAME: venue_map()}, make_settings(), Metrics())
    session = manager.build(SessionSpec(map_name=VENUE_NAME, particles=1000, odometry_source="vio"))
    assert filter_config(CONDITIONS["phone-vio"], 1000) == session.filter.config
    assert session.filter.config.odometry_source == "vio"
    # The idealized conditions keep the library's default filter.
    assert filter_config(CONDITIONS["barometer"], 1000) == FilterConfig(particles=1000)


def test_the_pdr_phone_conditions_filter_as_a_session_with_pdr_odometry() -> None:
    manager = SessionManager({VENUE_NAME: venue_map()}, make_settings(), Metrics())
    for name, fov in (("phone-pdr-180", 180.0), ("phone-pdr-66", 66.0)):
        spec = SessionSpec(
            map_name=VENUE_NAME,
            particles=1000,
            odometry_source="pdr",
            sensor=SensorSpec(fov_deg=fov),
        )
        session = manager.build(spec)
        assert filter_config(CONDITIONS[name], 1000) == session.filter.config
        assert session.filter.config.odometry_source == "pdr"


def test_a_report_of_fresh_seeds_names_them() -> None:
    text = markdown([], seconds=1.0, particles=1000, seeds=2, first_seed=10)
    assert "`bearings experiments --suite venue --first-seed 10 --seeds 2`" in text
    assert "2 seeds per condition, 10 to 11" in text
    assert "--first-seed" not in markdown([], seconds=1.0, particles=1000, seeds=10)


def test_the_walks_go_at_the_rate_asked_and_the_report_says_so() -> None:
    # `--rate-hz 10` for the venue suite: the same walk sent 10 frames a second, twice
    # the frames over the same time, the barometer's readings with them.
    cond = CONDITIONS["phone-vio-66"]
    _, five, _ = _walk(0, cond)
    _, ten, _ = _walk(0, cond, rate_hz=10.0)
    t5 = np.array([vf.frame.t for vf in five])
    t10 = np.array([vf.frame.t for vf in ten])
    assert np.median(np.diff(t5)) == pytest.approx(0.2)
    assert np.median(np.diff(t10)) == pytest.approx(0.1)
    assert t10[-1] == pytest.approx(t5[-1], abs=1.0)
    assert all(vf.altitude is not None for vf in ten)
    rows: list[dict[str, object]] = []
    text = markdown(rows, seconds=1.0, particles=100, seeds=1, rate_hz=10.0)
    assert "--rate-hz 10" in text and "10 frames/s" in text
    assert "--rate-hz" not in markdown(rows, seconds=1.0, particles=100, seeds=1)


def test_the_command_line_passes_the_rate_and_seeds_to_the_venue_suite(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`bearings experiments --suite venue --rate-hz 10 --first-seed 3`: the walks the
    suite runs are asked for at that rate and from that seed (the whole suite's run is
    the committed docs/results/venue-10hz; here only what the command line hands it)."""
    from app.experiments import cli, venue

    asked: dict[str, object] = {}

    def record(out: Path, **kwargs: object) -> list[dict[str, object]]:
        asked.update(kwargs, out=out)
        return []

    monkeypatch.setattr(venue, "run", record)
    monkeypatch.setattr(venue, "markdown_table", lambda rows: "")
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(
        ["--suite", "venue", "--rate-hz", "10", "--first-seed", "3", "--seeds", "2",
         "--particles", "500", "--workers", "1", "--out", str(tmp_path)]
    )  # fmt: skip
    assert cli.run(args) == 0
    assert asked == {
        "out": tmp_path, "seeds": 2, "particles": 500, "workers": 1, "first_seed": 3,
        "rate_hz": 10.0,
    }  # fmt: skip
    for bad in ("0", "-5", "nan"):
        with pytest.raises(SystemExit, match="--rate-hz"):
            cli.run(
                parser.parse_args(["--suite", "venue", "--rate-hz", bad, "--out", str(tmp_path)])
            )
