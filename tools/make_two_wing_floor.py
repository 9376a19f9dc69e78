"""Generate the two-wing office floor as a venue would hand it over, then import it.

Writes, under ``app/maps/examples/two_wing_office/``:

* ``floor.png`` + ``floor.yaml``: a ROS map_server occupancy grid (5 cm pixels, PNG) of a
  38 m x 24 m floor: two wings, each a 2 m corridor with three rooms on either side,
  joined by a lobby; 15 cm inner walls, 25 cm outer walls, 90 cm doorways left open.
* ``objects.csv``: ``class,x,y,label`` rows in map metres (doors in the doorways,
  windows in the outer walls, desks, chairs, tables, sinks, whiteboards, extinguishers,
  printers, plants, sofas, signs).
* ``rooms.geojson``: the rooms, corridors and lobby as named polygons (map metres).

The two wings have the same rooms and doorways (translated by 21 m); only the
furniture and a few wall fittings differ, as in a real building, so a person in a
corridor cannot tell the wings apart at a glance.

Then run (the bundled map is made *through the importer*)::

    python -m app.cli map import --occupancy app/maps/examples/two_wing_office/floor.yaml \\
        --objects app/maps/examples/two_wing_office/objects.csv \\
        --regions app/maps/examples/two_wing_office/rooms.geojson \\
        --description "..." --out app/resources/maps/two_wing_office.json
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from PIL import Image

RES = 0.05
ORIGIN = (-1.0, -1.0)
WIDTH_M, HEIGHT_M = 38.0, 24.0
IMG_W = round((WIDTH_M + 2.0) / RES)
IMG_H = round((HEIGHT_M + 2.0) / RES)
FREE, OCCUPIED, UNKNOWN = 254, 0, 205
#: Corridor band (y), wing extents (x) and the lobby between the wings.
CORR_Y0, CORR_Y1 = 11.0, 13.0
WINGS = {"West": 0.0, "East": 21.0}  # x offset of each wing
WING_W = 17.0
ROOM_W = WING_W / 3.0
DOOR_W = 0.9


class Canvas:
    """An occupancy image drawn in map metres (y up)."""

    def __init__(self) -> None:
        self.img = np.full((IMG_H, IMG_W), UNKNOWN, dtype=np.uint8)

    def _rows(self, y0: float, y1: float) -> slice:
        r0 = IMG_H - round((max(y0, y1) - ORIGIN[1]) / RES)
        r1 = IMG_H - round((min(y0, y1) - ORIGIN[1]) / RES)
        return slice(max(r0, 0), min(r1, IMG_H))

    def _cols(self, x0: float, x1: float) -> slice:
        c0 = round((min(x0, x1) - ORIGIN[0]) / RES)
        c1 = round((max(x0, x1) - ORIGIN[0]) / RES)
        return slice(max(c0, 0), min(c1, IMG_W))

    def rect(self, x0: float, y0: float, x1: float, y1: float, value: int) -> None:
        self.img[self._rows(y0, y1), self._cols(x0, x1)] = value

    def hwall(self, x0: float, x1: float, y: float, t: float = 0.15) -> None:
        self.rect(x0 - t / 2, y - t / 2, x1 + t / 2, y + t / 2, OCCUPIED)

    def vwall(self, x: float, y0: float, y1: float, t: float = 0.15) -> None:
        self.rect(x - t / 2, y0 - t / 2, x + t / 2, y1 + t / 2, OCCUPIED)

    def doorway(self, x: float, y: float, horizontal_wall: bool, width: float = DOOR_W) -> None:
        """Open a gap in a wall (clear it to free space)."""
        if horizontal_wall:
            self.rect(x - width / 2, y - 0.2, x + width / 2, y + 0.2, FREE)
        else:
            self.rect(x - 0.2, y - width / 2, x + 0.2, y + width / 2, FREE)


def rooms_of_wing(wing: str, x0: float) -> list[tuple[str, float, float, float, float]]:
    """(name, x0, y0, x1, y1) of the wing's six rooms."""
    out = []
    for i in range(3):
        a, b = x0 + i * ROOM_W, x0 + (i + 1) * ROOM_W
        out.append((f"{wing} {i + 1}N", a, CORR_Y1, b, HEIGHT_M))
        out.append((f"{wing} {i + 1}S", a, 0.0, b, CORR_Y0))
    return out


#: What each room is, by wing: this is where the wings differ.
ROOM_USE = {
    "West 1N": ("Office W1", "office"),
    "West 2N": ("Meeting room Rhine", "meeting"),
    "West 3N": ("Office W3", "office"),
    "West 1S": ("Kitchen", "kitchen"),
    "West 2S": ("Office W2", "office"),
    "West 3S": ("Washrooms west", "washroom"),
    "East 1N": ("Meeting room Danube", "meeting"),
    "East 2N": ("Office E2", "office"),
    "East 3N": ("Library", "library"),
    "East 1S": ("Office E1", "office"),
    "East 2S": ("Print room", "print"),
    "East 3S": ("Office E3", "office"),
}


def furnish(use: str, x0: float, y0: float, x1: float, y1: float, north: bool) -> list:
    """Objects inside one room (kept 0.4 m or more from its walls)."""
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    far_y = y1 - 0.5 if north else y0 + 0.5  # the wall away from the corridor
    items: list[tuple[str, float, float, str]] = []
    if use == "office":
        for k, fx in enumerate((x0 + 1.2, x1 - 1.2)):
            dy = far_y - (1.2 if north else -1.2)
            items += [("desk", fx, dy, ""), ("chair", fx, dy - (0.8 if north else -0.8), "")]
            if k == 0:
                items.append(("plant", x0 + 0.5, far_y, ""))
        items.append(("desk", cx, cy + (0.5 if north else -0.5), ""))
    elif use == "meeting":
        items += [("table", cx, cy, "meeting table"), ("whiteboard", x0 + 0.08, cy, "")]
        for dx in (-1.0, 1.0):
            for dy in (-0.9, 0.9):
                items.append(("chair", cx + dx, cy + dy, ""))
    elif use == "kitchen":
        items += [
            ("sink", x0 + 1.0, far_y, "kitchen sink"),
            ("table", cx, cy, "kitchen table"),
            ("chair", cx - 0.9, cy, ""),
            ("chair", cx + 0.9, cy, ""),
            ("sign", x1 - 0.08, cy, "coffee"),
        ]
    elif use == "washroom":
        items += [("sink", x0 + 1.2 + 1.2 * k, far_y, "") for k in range(3)]
        items.append(("sign", x0 + 0.08, cy, "washrooms"))
    elif use == "library":
        items += [
            ("table", cx, cy, "reading table"),
            ("chair", cx - 0.9, cy, ""),
            ("chair", cx + 0.9, cy, ""),
            ("sofa", x1 - 1.0, far_y, ""),
            ("plant", x0 + 0.5, far_y, ""),
            ("whiteboard", x1 - 0.08, cy, ""),
        ]
    elif use == "print":
        items += [
            ("printer", x0 + 1.0, far_y, "large printer"),
            ("printer", x1 - 1.0, far_y, ""),
            ("table", cx, cy, "sorting table"),
            ("sign", x0 + 0.08, cy, "print room"),
        ]
    return items


def build(out_dir: Path) -> None:
    c = Canvas()
    c.rect(0, 0, WIDTH_M, HEIGHT_M, FREE)
    objects: list[tuple[str, float, float, str]] = []
    regions: list[tuple[str, list[list[float]]]] = []
    # Outer walls (25 cm).
    c.hwall(0, WIDTH_M, 0, 0.25)
    c.hwall(0, WIDTH_M, HEIGHT_M, 0.25)
    c.vwall(0, 0, HEIGHT_M, 0.25)
    c.vwall(WIDTH_M, 0, HEIGHT_M, 0.25)
    # Lobby between the wings: walls along x = 17 and x = 21 except the corridor mouths.
    for x in (WING_W, WINGS["East"]):
        c.vwall(x, 0, CORR_Y0)
        c.vwall(x, CORR_Y1, HEIGHT_M)
    lobby_x0, lobby_x1 = WING_W, WINGS["East"]
    lobby = [[lobby_x0, 0], [lobby_x1, 0], [lobby_x1, HEIGHT_M], [lobby_x0, HEIGHT_M]]
    regions.append(("Lobby", lobby))
    for wing, x0 in WINGS.items():
        x1 = x0 + WING_W
        c.hwall(x0, x1, CORR_Y0)
        c.hwall(x0, x1, CORR_Y1)
        regions.append(
            (f"{wing} corridor", [[x0, CORR_Y0], [x1, CORR_Y0], [x1, CORR_Y1], [x0, CORR_Y1]])
        )
        for i in (1, 2):
            xw = x0 + i * ROOM_W
            c.vwall(xw, 0, CORR_Y0)
            c.vwall(xw, CORR_Y1, HEIGHT_M)
        for key, a, y0, b, y1 in rooms_of_wing(wing, x0):
            name, use = ROOM_USE[key]
            north = y0 == CORR_Y1
            regions.append((name, [[a, y0], [b, y0], [b, y1], [a, y1]]))
            # Doorway onto the corridor, same place in both wings.
            dx = a + (1.0 if north else ROOM_W - 1.0)
            dy = CORR_Y1 if north else CORR_Y0
            c.doorway(dx, dy, horizontal_wall=True)
            objects.append(("door", dx, dy, name))
            # Two windows in the outer wall.
            wy = HEIGHT_M if north else 0.0
            for f in (0.3, 0.7):
                objects.append(("window", a + f * ROOM_W, wy, ""))
            objects += furnish(use, a, y0, b, y1, north)
    # Lobby: the main entrance (a closed door in the outer wall, as the robot mapped it),
    # stairs sign, sofas, plants, reception.
    lx = (lobby_x0 + lobby_x1) / 2
    objects += [
        ("door", lx, 0.0, "main entrance"),
        ("sign", lx, HEIGHT_M, "stairs and lifts"),
        ("sofa", lobby_x0 + 0.8, 4.0, ""),
        ("sofa", lobby_x1 - 0.8, 4.0, ""),
        ("plant", lobby_x0 + 0.5, 0.6, ""),
        ("plant", lobby_x1 - 0.5, 0.6, ""),
        ("table", lx, 17.5, "reception desk"),
        ("extinguisher", lobby_x0 + 0.08, 8.0, ""),
    ]
    # Corridor fittings: extinguishers and signs, placed differently in each wing.
    objects += [
        ("extinguisher", 0.08, 12.0, "west end"),
        ("extinguisher", 8.0, CORR_Y1, ""),
        ("sign", 12.0, CORR_Y0, "exit"),
        ("extinguisher", WIDTH_M - 0.08, 12.0, "east end"),
        ("extinguisher", 27.5, CORR_Y0, ""),
        ("printer", 36.5, CORR_Y1 - 0.4, "corridor printer"),
        ("plant", 22.0, CORR_Y0 + 0.4, ""),
    ]
    out_dir.mkdir(parents=True, exist_ok=True)
    Image.fromarray(c.img, mode="L").save(out_dir / "floor.png")
    (out_dir / "floor.yaml").write_text(
        "image: floor.png\n"
        f"resolution: {RES}\n"
        f"origin: [{ORIGIN[0]}, {ORIGIN[1]}, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        encoding="utf-8",
    )
    with (out_dir / "objects.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["class", "x", "y", "label"])
        for cls, x, y, label in objects:
            w.writerow([cls, round(x, 3), round(y, 3), label])
    features = [
        {
            "type": "Feature",
            "properties": {"name": name},
            "geometry": {"type": "Polygon", "coordinates": [[*poly, poly[0]]]},
        }
        for name, poly in regions
    ]
    (out_dir / "rooms.geojson").write_text(
        json.dumps({"type": "FeatureCollection", "features": features}, indent=1) + "\n",
        encoding="utf-8",
    )
    classes = sorted({o[0] for o in objects})
    print(
        f"{out_dir}: {IMG_W} x {IMG_H} px, {len(objects)} objects of {len(classes)} classes "
        f"({', '.join(classes)}), {len(regions)} regions"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", type=Path, default=Path("app/maps/examples/two_wing_office"))
    build(parser.parse_args().out_dir)


if __name__ == "__main__":
    main()
