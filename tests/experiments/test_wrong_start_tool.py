"""tools/wrong_start.py: sessions given a start the walk did not begin at."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.experiments import phone
from app.localization.types import Pose
from tools.wrong_start import given_start, main


def test_the_starts_given_are_off_as_named_and_in_free_space() -> None:
    suite, _ = phone.suite_map("office_suite")
    truth = Pose(*(float(v) for v in suite.free_space.sample(1, np.random.default_rng(3))[0]), 0.5)
    right = given_start("right", "tight", 0)(suite, truth)
    turned = given_start("turned", "default", 0)(suite, truth)
    off = given_start("2m", "tight", 0)(suite, truth)
    assert right is not None and turned is not None and off is not None
    assert (right.x, right.y, right.theta_rad) == (truth.x, truth.y, truth.theta_rad)
    assert right.std_xy_m == 0.05 and right.std_theta_rad == pytest.approx(math.radians(1.0))
    assert turned.theta_rad == pytest.approx(truth.theta_rad + math.pi)
    assert turned.std_xy_m == 0.3
    assert math.hypot(off.x - truth.x, off.y - truth.y) == pytest.approx(2.0)
    assert suite.free_space.is_free(np.array([off.x]), np.array([off.y]))[0]


def test_a_short_run_prints_its_rows_and_totals(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--maps", "paper_office", "--conditions", "vio-360", "--kinds", "right",
                 "--seeds", "1", "--workers", "1"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "| paper_office | vio-360 | right | tight |" in out
    assert "given right: 0 and 0" in out


def test_unknown_names_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, said in (
        (["--maps", "nowhere"], "no map 'nowhere'"),
        (["--conditions", "vio-99"], "no phone condition 'vio-99'"),
        (["--kinds", "3m"], "no kind '3m'"),
    ):
        with pytest.raises(SystemExit):
            main(argv)
        assert said in capsys.readouterr().err
