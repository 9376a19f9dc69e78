"""How long `bearings map import --imdf` takes on a station-sized venue (issue 28).

    PYTHONPATH=. python benchmarks/imdf_import.py             # 4 levels, median of 3 runs
    PYTHONPATH=. python benchmarks/imdf_import.py --levels 6 --repeats 5 --json
    PYTHONPATH=. python benchmarks/imdf_import.py --imdf DIR_OR_ZIP   # a venue of yours

Without ``--imdf``, writes the synthetic venue of ``tools/make_imdf_venue.py`` (per
level 184 units, 945 fixtures, 180 openings, 30 amenities) as a .zip. Then times, in
this process, the importer alone (read, project, walls, objects, connectors) and the
whole command (import, ``map check`` with the free-space grid, writing the file), in
wall-clock and in this process's CPU seconds (steadier on a shared machine); and the
command as a user runs it, ``python -m app.cli map import --imdf ...`` in a fresh
process (interpreter start and imports included), in wall-clock. Imports and compiled
kernels are warmed by one run first. Medians of ``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from app.cli import main as bearings
from app.maps.importers.imdf import import_imdf
from tools.make_imdf_venue import venue, write


def _quiet(args: list[str]) -> int:
    with contextlib.redirect_stdout(io.StringIO()):
        return bearings(args)


def _size(path: Path) -> int:
    """Bytes of a .zip, or of a folder's files."""
    if path.is_file():
        return path.stat().st_size
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def _time_command(command: list[str], repeats: int) -> float:
    """Median wall-clock seconds of ``python -m app.cli COMMAND`` in a fresh process."""
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "app.cli", *command], check=True, capture_output=True)
        runs.append(time.perf_counter() - t0)
    return statistics.median(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--imdf", type=Path, help="an IMDF folder or .zip to time instead")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        result: dict[str, object] = {}
        if args.imdf is None:
            archive = Path(tmp) / "venue.zip"
            features = venue(args.levels, np.random.default_rng(0))
            write(features, archive)
            result = {
                "levels": args.levels,
                "units": len(features["unit"]),
                "fixtures": len(features["fixture"]),
                "openings": len(features["opening"]),
                "amenities": len(features["amenity"]),
                "unpacked_bytes": sum(
                    len(json.dumps({"type": "FeatureCollection", "features": v}))
                    for v in features.values()
                ),
            }
        else:
            archive = args.imdf
        result["input_bytes"] = _size(archive)
        out = Path(tmp) / "venue.json"
        command = ["map", "import", "--imdf", str(archive), "--out", str(out)]
        assert _quiet(command) == 0  # warm-up, and the map passes its check
        importer, importer_cpu, whole, whole_cpu = [], [], [], []
        for _ in range(args.repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            import_imdf(archive, "venue")
            importer.append(time.perf_counter() - t0)
            importer_cpu.append(time.process_time() - c0)
            t0, c0 = time.perf_counter(), time.process_time()
            assert _quiet(command) == 0
            whole.append(time.perf_counter() - t0)
            whole_cpu.append(time.process_time() - c0)
        made = json.loads(out.read_text())
        result |= {
            "made_levels": len(made.get("levels", [])),
            "walls": len(made["walls"]),
            "objects": len(made["objects"]),
            "connectors": len(made.get("connectors", [])),
            "import_s_median": round(statistics.median(importer), 3),
            "import_cpu_s_median": round(statistics.median(importer_cpu), 3),
            "command_s_median": round(statistics.median(whole), 3),
            "command_cpu_s_median": round(statistics.median(whole_cpu), 3),
            "cli_s_median": round(_time_command(command, args.repeats), 3),
            "check_cli_s_median": round(_time_command(["map", "check", str(out)], args.repeats), 3),
        }
    if args.json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        print(f"{key:>20}: {value}")


if __name__ == "__main__":
    main()
