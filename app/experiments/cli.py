"""`bearings experiments`: regenerate Tables I-IV and Figures 5-10 from scratch."""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from tqdm import tqdm

from app.experiments.protocol import cells
from app.experiments.report import markdown, summarize
from app.experiments.runner import paper_office, run_all


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=int, default=10, help="seeds per cell of Tables I-III")
    parser.add_argument(
        "--table4-seeds", type=int, default=3, help="seeds per cell of Table IV (default 3)"
    )
    parser.add_argument(
        "--tables", default="I,II,III,IV", help="comma-separated subset of I,II,III,IV"
    )
    parser.add_argument("--particles", type=int, default=10_000, help="particles (default 10000)")
    parser.add_argument("--out", type=Path, default=Path("results"), help="output directory")
    parser.add_argument(
        "--workers", type=int, default=os.cpu_count() or 1, help="processes (default: all cores)"
    )
    parser.add_argument(
        "--quick", action="store_true", help="smoke run: 2 seeds, 1 for Table IV, 1000 particles"
    )
    parser.add_argument(
        "--suite",
        choices=("tables", "integrity", "building", "phone", "venue"),
        default="tables",
        help="tables: the paper's Tables I-IV (default); integrity: the hard-cases suite "
        "(--quick: five scenarios, 2 seeds); building: a walk through the bundled two-wing "
        "floor (global start, 180 deg camera, clutter, kidnap between wings); phone: walks "
        "as a real phone sends them (docs/results/phone.md); venue: three floors by lift, "
        "stairs and escalators, with and without a drifting barometer",
    )
    parser.add_argument(
        "--first-seed",
        type=int,
        default=0,
        help="phone and venue: the first seed (seeds K to K + --seeds - 1), to check "
        "fresh walks beside the committed results' seeds 0-9 (default 0)",
    )
    parser.add_argument(
        "--rate-hz",
        type=float,
        default=None,
        help="phone and venue: frames a second the phone sends (default 5; a phone app "
        "often sends 10)",
    )
    parser.add_argument(
        "--scenarios",
        default=None,
        help="integrity and phone: comma-separated MAP or MAP/CONDITION (* for any map), "
        "e.g. 'symmetric_room,*/compass-180'",
    )


def run(args: argparse.Namespace) -> int:
    if args.first_seed < 0:
        raise SystemExit("bearings experiments: need --first-seed >= 0")
    if args.first_seed and args.suite not in ("phone", "venue"):
        raise SystemExit(
            "bearings experiments: --first-seed is for the phone and venue suites, "
            f"not {args.suite}"
        )
    if args.rate_hz is not None and args.suite not in ("phone", "venue"):
        raise SystemExit(
            f"bearings experiments: --rate-hz is for the phone and venue suites, not {args.suite}"
        )
    if args.rate_hz is not None and not 0.5 <= args.rate_hz <= 60.0:
        raise SystemExit(f"bearings experiments: need 0.5 <= --rate-hz <= 60, got {args.rate_hz}")
    if args.suite == "integrity":
        return _run_integrity(args)
    if args.suite == "building":
        return _run_building(args)
    if args.suite == "phone":
        return _run_phone(args)
    if args.suite == "venue":
        return _run_venue(args)
    tables = tuple(t.strip().upper() for t in args.tables.split(",") if t.strip())
    seeds, seeds4, particles = args.seeds, args.table4_seeds, args.particles
    if args.quick:
        seeds, seeds4, particles = min(seeds, 2), 1, min(particles, 1000)
    if seeds < 1 or seeds4 < 1 or particles < 100:
        raise SystemExit("bearings experiments: need --seeds >= 1 and --particles >= 100")
    try:
        todo = cells(tables)
    except ValueError as exc:
        raise SystemExit(f"bearings experiments: {exc}") from None
    jobs = [
        (cell, seed, particles)
        for cell in todo
        for seed in range(seeds4 if cell.table == "IV" else seeds)
    ]
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    with tqdm(total=len(jobs), desc="experiment runs", unit="run") as bar:
        runs = run_all(jobs, max(1, args.workers), bar.update)
    seconds = time.perf_counter() - started
    rows = summarize(runs)
    (out / "tables.json").write_text(json.dumps(rows, indent=1), encoding="utf-8")
    (out / "tables.md").write_text(
        markdown(rows, seconds=seconds, particles=particles), encoding="utf-8"
    )
    # matplotlib only when figures are drawn: `bearings serve` builds this parser too.
    from app.experiments.figures import figures

    written = figures(runs, paper_office(), out)
    print(
        f"wrote {out / 'tables.json'}, {out / 'tables.md'} and {len(written)} figures "
        f"in {seconds:.0f} s"
    )
    return 0


def _run_integrity(args: argparse.Namespace) -> int:
    from app.experiments import integrity

    seeds = min(args.seeds, 2) if args.quick else args.seeds
    if seeds < 1 or args.particles < 100:
        raise SystemExit("bearings experiments: need --seeds >= 1 and --particles >= 100")
    try:
        summary = integrity.run(
            args.out, seeds=seeds, particles=args.particles, workers=max(1, args.workers),
            quick=args.quick, select=args.scenarios,
        )  # fmt: skip
    except ValueError as exc:
        raise SystemExit(f"bearings experiments: {exc}") from None
    print(integrity.markdown_table(summary))
    print(f"wrote {args.out / 'integrity.md'}, integrity.json and integrity.png")
    return 0


def _run_building(args: argparse.Namespace) -> int:
    from app.experiments import building

    seeds = min(args.seeds, 2) if args.quick else args.seeds
    if seeds < 1 or args.particles < 100:
        raise SystemExit("bearings experiments: need --seeds >= 1 and --particles >= 100")
    rows = building.run(
        args.out, seeds=seeds, particles=args.particles, workers=max(1, args.workers),
        quick=args.quick,
    )  # fmt: skip
    print(building.markdown_table(rows))
    print(f"wrote {args.out / 'building.md'}, building.json and building.png")
    return 0


def _run_phone(args: argparse.Namespace) -> int:
    from app.experiments import phone

    seeds = min(args.seeds, 2) if args.quick else args.seeds
    if seeds < 1 or args.particles < 100:
        raise SystemExit("bearings experiments: need --seeds >= 1 and --particles >= 100")
    try:
        summary = phone.run(
            args.out, seeds=seeds, particles=args.particles, workers=max(1, args.workers),
            quick=args.quick, select=args.scenarios, first_seed=args.first_seed,
            rate_hz=args.rate_hz,
        )  # fmt: skip
    except ValueError as exc:
        raise SystemExit(f"bearings experiments: {exc}") from None
    print(phone.markdown_table(summary))
    print(f"wrote {args.out / 'phone.md'}, phone.json and phone.png")
    return 0


def _run_venue(args: argparse.Namespace) -> int:
    from app.experiments import venue

    seeds = min(args.seeds, 2) if args.quick else args.seeds
    if seeds < 1 or args.particles < 100:
        raise SystemExit("bearings experiments: need --seeds >= 1 and --particles >= 100")
    rows = venue.run(
        args.out, seeds=seeds, particles=args.particles, workers=max(1, args.workers),
        first_seed=args.first_seed, rate_hz=args.rate_hz,
    )  # fmt: skip
    print(venue.markdown_table(rows))
    print(f"wrote {args.out / 'venue.md'} and venue.json")
    return 0
