"""CPU a frame of the service's sessions, in one process: no network, no event loop.

Replays `load.py`'s walk (the paper office there and back) for N sessions built by the
service's own `SessionManager`, interleaved frame by frame as a worker interleaves its
people, every frame through the path a stream takes (`Frame` validation, `frame_input`,
`Session.process_sync`, `frame_result_json`). After ``--warmup`` frames of each session
(their global localization), it reports the process's CPU seconds per frame over the
next ``--frames``: what a converged walk costs a worker's core, without the sockets'
share and much less sensitive to other load than latencies are. Compare two versions by
running each from its own checkout, alternated, at the same hour.

    python -m benchmarks.replay --sessions 60 --frames 100
"""

from __future__ import annotations

import argparse
import json
import time

from app.api.convert import frame_input, frame_result_json
from app.api.schemas import Frame
from app.config import Settings
from app.maps.check import load_map_dir
from app.resources import bundled_maps_dir
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.types import SessionSpec
from benchmarks.load import paper_walk_frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sessions", type=int, default=60)
    parser.add_argument("--warmup", type=int, default=40, help="frames of each session first")
    parser.add_argument("--frames", type=int, default=100, help="timed frames of each session")
    parser.add_argument("--particles", type=int, default=10_000)
    parser.add_argument(
        "--phone-rate",
        type=float,
        default=None,
        help="frames as a phone sends them at this rate, with timestamps "
        "(load.paper_walk_frames); default: the paper's walk, no timestamps",
    )
    args = parser.parse_args()
    texts = [json.dumps(f) for f in paper_walk_frames(args.phone_rate)]
    manager = SessionManager(
        load_map_dir(bundled_maps_dir()), Settings(max_sessions=max(args.sessions, 1)), Metrics()
    )
    sessions = [
        manager.build(SessionSpec(map_name="paper_office", particles=args.particles, seed=s))
        for s in range(args.sessions)
    ]
    # Each session starts at its own point of the walk, never running off its end.
    room = len(texts) - args.warmup - args.frames
    starts = [(7 * s) % max(room, 1) for s in range(args.sessions)]

    def play(first: int, last: int) -> None:
        for k in range(first, last):
            for session, start in zip(sessions, starts, strict=True):
                frame = Frame.model_validate_json(texts[start + k])
                frame_result_json(session.process_sync(frame_input(frame)))

    play(0, args.warmup)
    cpu = time.process_time()
    play(args.warmup, args.warmup + args.frames)
    per_frame_ms = 1e3 * (time.process_time() - cpu) / (args.frames * args.sessions)
    print(
        json.dumps(
            {
                "sessions": args.sessions,
                "frames_each": args.frames,
                "phone_rate": args.phone_rate,
                "cpu_ms_per_frame": round(per_frame_ms, 4),
            }
        )
    )


if __name__ == "__main__":
    main()
