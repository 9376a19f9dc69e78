"""The `bearings` command line: subcommands, help, settings from flags and environment."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from app.cli import build_parser, main, settings_from_args


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_help_lists_the_four_subcommands() -> None:
    proc = run_cli("--help")  # the real entry point, in a fresh interpreter
    assert proc.returncode == 0
    for sub in ("serve", "demo", "experiments", "bench"):
        assert sub in proc.stdout


def help_of(sub: str, capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args([sub, "--help"])
    assert info.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("sub", ["serve", "demo", "experiments", "bench"])
def test_every_flag_is_explained(sub: str, capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    sub_parser = parser._subparsers._group_actions[0].choices[sub]  # type: ignore[union-attr]
    for action in sub_parser._actions:
        assert action.help, f"{sub} {action.option_strings} has no help"
    assert f"usage: bearings {sub}" in help_of(sub, capsys)


def test_serve_flags_match_the_contract(capsys: pytest.CaptureFixture[str]) -> None:
    out = help_of("serve", capsys)
    for flag in ("--host", "--port", "--maps", "--viser-port", "--no-viser"):
        assert flag in out


def test_flags_override_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("BEARINGS_VISER_PORT", "9001")
    monkeypatch.setenv("BEARINGS_PORT", "8123")
    args = build_parser().parse_args(["serve", "--port", "9000", "--no-viser"])
    s = settings_from_args(args)
    assert (s.port, s.viser_port, s.viser) == (9000, 9001, False)


def test_bench_prints_one_json_object(capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "bench",
                "--particles",
                "500",
                "--detections",
                "4",
                "--objects",
                "12",
                "--steps",
                "5",
                "--json",
            ]
        )
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    assert result["steps"] == 5 and result["median_ms_per_step"] > 0
    assert result["particles"] == 500 and result["objects"] == 12


def test_bench_refuses_nonsense() -> None:
    proc = run_cli("bench", "--particles", "0")
    assert proc.returncode != 0 and "--particles must be at least 1" in proc.stderr
