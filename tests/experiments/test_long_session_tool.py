"""tools/long_session.py and the phone walk's passes: the route there and back in one
session, each pass reported apart; bad arguments refused by name."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.experiments import phone
from tools.long_session import main


def test_a_walk_of_three_passes_goes_there_back_and_there_again() -> None:
    scenario = phone.Scenario("paper_office", "vio-360")
    _, route = phone.suite_map(scenario.map_name)
    once = phone.walk_of(scenario)
    thrice = phone.walk_of(scenario, passes=3)
    assert once.path == tuple(route)
    back = tuple(route[::-1])
    assert thrice.path == tuple(route) + back[1:] + tuple(route)[1:]
    with pytest.raises(ValueError, match="passes"):
        phone.walk_of(scenario, passes=0)


def test_the_tool_reports_each_pass_of_a_session(tmp_path: Path) -> None:
    out = tmp_path / "long.md"
    assert main(["--rows", "paper_office/vio-360", "--passes", "2", "--seeds", "1",
                 "--workers", "1", "--out", str(out)]) == 0  # fmt: skip
    text = out.read_text()
    lines = [ln for ln in text.splitlines() if ln.startswith("| paper_office/vio-360 |")]
    assert [ln.split("|")[2].strip() for ln in lines] == ["1", "2"]
    frames = [int(ln.split("|")[3]) for ln in lines]
    # Two passes of one route: as many frames each, twice the route's once.
    once = phone.run_scenario(phone.Scenario("paper_office", "vio-360"), 0, 500)
    assert abs(frames[0] - frames[1]) <= 1
    assert abs(sum(frames) - 2 * once.t.size) <= 2
    assert np.isfinite(float(lines[0].split("|")[6]))


def test_bad_rows_are_refused_by_name() -> None:
    for bad in ("paper_office", "nowhere/vio-360", "paper_office/known-start-360"):
        with pytest.raises(SystemExit):
            main(["--rows", bad, "--seeds", "1"])
    with pytest.raises(SystemExit):
        main(["--rows", "paper_office/vio-360", "--passes", "0"])
