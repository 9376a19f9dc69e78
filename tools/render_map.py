"""Render a map file (and optionally the occupancy image it came from) to a PNG.

    python -m tools.render_map app/resources/maps/two_wing_office.json \\
        docs/img/two_wing_office.png \\
        --occupancy app/maps/examples/two_wing_office/floor.yaml
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from app.maps.check import load_map

MARKERS = "osD^v<>phP*X"


def render(map_path: Path, out: Path, occupancy: Path | None = None) -> None:
    m = load_map(map_path)
    x0, y0, x1, y1 = m.bounds
    fig, ax = plt.subplots(figsize=(12, 12 * (y1 - y0 + 2) / (x1 - x0 + 2) + 0.8), dpi=110)
    if occupancy is not None:
        from app.maps.importers.occupancy import read_occupancy

        occ = read_occupancy(occupancy)
        h, w = occ.occupied.shape
        ox, oy, _ = occ.origin
        ax.imshow(
            np.where(occ.occupied, 0.55, 1.0), cmap="gray", vmin=0, vmax=1,
            extent=(ox, ox + w * occ.resolution, oy, oy + h * occ.resolution), zorder=0,
        )  # fmt: skip
    for i, poly in enumerate(m.region_polygons):
        ring = np.vstack([poly, poly[:1]])
        ax.fill(ring[:, 0], ring[:, 1], color=plt.cm.Pastel2(i % 8), alpha=0.35, zorder=1)
        cx, cy = poly.mean(axis=0)
        ax.text(cx, cy, m.region_names[i], ha="center", va="center", fontsize=7, zorder=4)
    for xa, ya, xb, yb in m.walls:
        ax.plot([xa, xb], [ya, yb], color="black", lw=1.6, zorder=2)
    for k, (cls, members) in enumerate(m.class_members.items()):
        xy = m.object_xy[members]
        ax.scatter(
            xy[:, 0], xy[:, 1], marker=MARKERS[k % len(MARKERS)], s=28, zorder=3,
            color=plt.cm.tab20(k % 20), edgecolor="black", linewidth=0.4,
            label=f"{cls} ({len(members)})",
        )  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        f"{m.name}: {m.walls.shape[0]} walls, {m.object_count} objects of "
        f"{len(m.classes)} classes, {len(m.region_names)} regions"
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=6, fontsize=8, frameon=False)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    print(f"wrote {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description="Render a map file to a PNG.")
    parser.add_argument("map", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--occupancy", type=Path, help="the ROS YAML it was imported from")
    args = parser.parse_args()
    render(args.map, args.out, args.occupancy)


if __name__ == "__main__":
    main()
