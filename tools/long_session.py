"""Long sessions: a phone-suite walk there and back several times in one session.

The phone suite (``bearings experiments --suite phone``) walks each route once, about a
minute; a person wearing the service walks for much longer, through the same places again
and again, and what the filter learns on the way (objects it takes for moved or gone
from a stale map, the detector's hit rate, the odometry's scale) stays with the session.
This tool walks each scenario's route there and back ``--passes`` times in one session
(``app.experiments.phone.run_scenario``'s ``passes``) and reports each pass apart, as the
phone suite counts it: frames, confidently wrong (converged and more than 1 m off),
beyond protection (converged and farther off than ``protection_m``), availability
(converged among the frames within 0.5 m); and how many of the map's objects the
session had taken for gone from the world by its end (of them, moved: out of the sensor
model), which on a map as drawn should be none.

    python tools/long_session.py                                  # default rows, seeds 0-9
    python tools/long_session.py --out docs/results/long-session.md
    python tools/long_session.py --rows office_suite/pdr-360 --passes 6 --seeds 3
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Sequence

import numpy as np

from app.experiments import phone
from app.experiments.report import tool_results_head
from app.experiments.runner import map_jobs

#: Default scenarios: maps as drawn at VIO and PDR grade and through narrower cameras,
#: and the stale maps (objects moved, removed and added since the map was drawn).
ROWS = (
    "office_suite/vio-360",
    "office_suite/pdr-360",
    "office_suite/vio-180",
    "office_suite/pdr-pinhole66",
    "paper_office/vio-360",
    "door_corridor/vio-360",
    "office_suite/vio-stale-360",
    "office_suite/only-stale-map-360",
    "paper_office/vio-stale-360",
)


@dataclasses.dataclass(frozen=True)
class LongRun:
    """One session: its walk cut into passes, and the objects it had taken by its end."""

    row: str
    seed: int
    passes: list[phone.PhoneRun]
    gone: int
    moved: int


def _job(args: tuple[str, int, int]) -> LongRun:
    row, seed, passes = args
    scenario = phone.Scenario(*row.split("/"))
    sessions: list[object] = []

    def keep(session: object, frame: object, outcome: object) -> None:
        if not sessions:
            sessions.append(session)

    run = phone.run_scenario(scenario, seed, 10_000, on_frame=keep, passes=passes)
    unseen = sessions[0].filter.unseen  # type: ignore[attr-defined]
    gone = 0 if unseen is None else int(unseen.absent.sum())
    moved = 0 if unseen is None else int(unseen.moved.sum())
    # The passes are the same route there and back: as many frames each.
    parts = [
        dataclasses.replace(
            run,
            t=run.t[idx],
            err_m=run.err_m[idx],
            converged=run.converged[idx],
            protection_m=run.protection_m[idx],
            step_ms=run.step_ms[idx],
            alternatives=run.alternatives[idx],
        )
        for idx in np.array_split(np.arange(run.t.size), passes)
    ]
    return LongRun(row, seed, parts, gone, moved)


def table(runs: list[LongRun], passes: int) -> list[str]:
    """The markdown table: a line per scenario and pass, and the objects taken."""
    lines = [
        "| scenario | pass | frames | confidently wrong | beyond protection | availability "
        "| objects taken for gone (moved) by the end, all seeds |",
        "|---|---|---|---|---|---|---|",
    ]
    rows = list(dict.fromkeys(r.row for r in runs))
    for row in rows:
        mine = [r for r in runs if r.row == row]
        gone = sum(r.gone for r in mine)
        moved = sum(r.moved for r in mine)
        for k in range(passes):
            m = phone.metrics([r.passes[k] for r in mine])
            n = int(m["frames"])
            beyond = round(float(m["beyond_protection_share"]) * n)
            taken = f"{gone} ({moved})" if k == passes - 1 else ""
            lines.append(
                f"| {row} | {k + 1} | {n} | {m['wrong_frames']} | {beyond} "
                f"| {m['availability']:.3f} | {taken} |"
            )
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    phone.add_tool_arguments(parser, ROWS)
    parser.add_argument("--passes", type=int, default=4, help="there and back, in all")
    args = parser.parse_args(argv)
    try:
        scenarios = phone.parse_rows(args.rows)
    except ValueError as exc:
        parser.error(str(exc))
    rows = [f"{s.map_name}/{s.condition}" for s in scenarios]
    for row, s in zip(rows, scenarios, strict=True):
        if phone.CONDITIONS[s.condition].known_start is not None:
            parser.error(f"{row!r} stands still: it has no route to walk again")
    if args.passes < 1 or args.seeds < 1:
        parser.error("need --passes >= 1 and --seeds >= 1")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    started = time.perf_counter()
    jobs = [(r, s, args.passes) for r in rows for s in seeds]
    runs = list(map_jobs(_job, jobs, args.workers))
    lines = table(runs, args.passes)
    print(f"seeds {seeds.start}-{seeds.stop - 1}, {args.passes} passes")
    print("\n".join(lines))
    if args.out:
        head = tool_results_head(
            "Long sessions: each route walked there and back in one session",
            f"python tools/long_session.py {' '.join(argv or sys.argv[1:])}",
            time.perf_counter() - started,
            f"seeds {seeds.start}-{seeds.stop - 1} of each phone-suite scenario, "
            f"{args.passes} passes, 10000 particles.",
            (__doc__ or "").split("\n\n")[1],
        )
        with open(args.out, "w", encoding="utf-8") as out:
            out.write("\n".join([*head, *lines]) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
