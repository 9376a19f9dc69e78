"""The ``bearings`` command: serve, demo, experiments, bench, map.

Each subcommand's flags default to the matching ``BEARINGS_*`` setting (see
:mod:`app.config`), so a flag and its environment variable always agree.
"""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.config import Settings


def _add_server_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", help="address to listen on (BEARINGS_HOST, default 127.0.0.1)")
    p.add_argument("--port", type=int, help="HTTP API port (BEARINGS_PORT, default 8000)")
    p.add_argument(
        "--maps",
        type=Path,
        action="append",
        metavar="DIR",
        help="extra directory of map files, besides the bundled maps/; repeatable "
        "(BEARINGS_MAPS as a JSON list)",
    )
    p.add_argument(
        "--viser-port", type=int, help="port of the viser view (BEARINGS_VISER_PORT, default 8080)"
    )
    p.add_argument(
        "--no-viser",
        dest="viser",
        action="store_false",
        default=None,
        help="do not start the viser view (BEARINGS_VISER=false)",
    )
    p.add_argument("--log-level", help="debug, info, warning or error (BEARINGS_LOG_LEVEL)")
    p.add_argument("--max-sessions", type=int, help="most live sessions (BEARINGS_MAX_SESSIONS)")
    p.add_argument(
        "--session-idle-timeout-s",
        type=float,
        help="seconds before an idle session is removed (BEARINGS_SESSION_IDLE_TIMEOUT_S)",
    )
    p.add_argument(
        "--max-particles", type=int, help="most particles per session (BEARINGS_MAX_PARTICLES)"
    )
    p.add_argument(
        "--store",
        metavar="memory|redis://HOST:PORT/DB",
        help="where sessions live (BEARINGS_STORE, default memory): a Redis URL shares them "
        "between workers, checkpointed, so any worker resumes them",
    )
    p.add_argument(
        "--api-keys",
        dest="api_keys_file",
        type=Path,
        metavar="FILE",
        help="API key file: one 'KEY' or 'NAME KEY MAX_SESSIONS MAX_PARTICLES MAX_FRAMES_PER_S' "
        "a line (BEARINGS_API_KEYS_FILE); see docs/SECURITY.md",
    )
    p.add_argument(
        "--insecure-open",
        action="store_true",
        default=None,
        help="run without API keys on a host other than loopback (BEARINGS_INSECURE_OPEN)",
    )
    p.add_argument(
        "--allowed-origins",
        help="browser origins allowed for CORS and WebSocket, comma-separated "
        "(BEARINGS_ALLOWED_ORIGINS; default: same origin only)",
    )
    p.add_argument(
        "--viser-host",
        help="address the viser view listens on (BEARINGS_VISER_HOST, default 127.0.0.1)",
    )


def settings_from_args(args: argparse.Namespace) -> Settings:
    """Settings from the environment, overridden by every flag given on the command line."""
    from app.config import Settings

    overrides = {
        k: v for k, v in vars(args).items() if k in Settings.model_fields and v is not None
    }
    return Settings(**overrides)


#: The subcommands, in the order ``bearings --help`` lists them.
COMMANDS = ("serve", "demo", "experiments", "bench", "map")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole command line; given ``command``, only that subcommand's own flags are
    filled in, so ``bearings serve`` does not import the experiments, the benchmark or
    the map tools (they weigh a few hundred milliseconds of start-up)."""
    parser = argparse.ArgumentParser(
        prog="bearings",
        description="Bearing-only semantic self-localization service for blind and "
        "visually impaired people.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    serve = sub.add_parser("serve", help="run the HTTP/WebSocket service and the viser view")
    _add_server_flags(serve)

    demo = sub.add_parser(
        "demo", help="run the service with a simulated walk in the bundled paper office"
    )
    _add_server_flags(demo)

    exp = sub.add_parser("experiments", help="reproduce the paper's Tables I-III (and IV)")
    if command in (None, "experiments"):
        from app.experiments.cli import add_arguments as add_experiment_arguments

        add_experiment_arguments(exp)

    bench = sub.add_parser("bench", help="time a full filter step on a generated map")
    if command in (None, "bench"):
        from app.bench import add_arguments as add_bench_arguments

        add_bench_arguments(bench)

    maps = sub.add_parser("map", help="check map files; import ROS occupancy grids and GeoJSON")
    if command in (None, "map"):
        from app.maps.cli import add_arguments as add_map_arguments

        add_map_arguments(maps)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    # The command is the first word that is not a flag (the top level has only --help).
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(command if command in COMMANDS else None)
    args = parser.parse_args(argv)
    if args.command in ("serve", "demo"):
        # No garbage collection while the service starts (imports, kernels, maps): it
        # makes a few hundred thousand long-lived objects and almost no garbage, and
        # collecting meanwhile cost about 15 % of the start-up. Once started,
        # BearingsServer.startup freezes what start-up made and turns collection back on.
        gc.disable()
        try:
            from app.server import run

            return run(settings_from_args(args), demo=args.command == "demo")
        finally:
            gc.enable()
    if args.command == "experiments":
        from app.experiments.cli import run as run_experiments

        return run_experiments(args)
    if args.command == "bench":
        from app.bench import run as run_bench

        return run_bench(args)
    if args.command == "map":
        from app.maps.cli import run as run_map

        return run_map(args)
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
