"""Maps of the integrity suite, made in code: buildings that fool a filter.

Each map comes with a walk (waypoints) and a kidnap destination. They are built to be
hard on purpose:

* ``rotation_room``: a 12 x 8 m open office whose windows and tables are the same
  under a 180 deg rotation about its centre; only the door breaks the symmetry. The
  walk starts with the door behind the person.
* ``symmetric_room``: the rotation room without its door: exactly the same under the
  half turn, so without a compass no amount of walking tells the two ways round apart.
* ``mirror_room``: a 12 x 8 m room symmetric under reflection in x = 6; one door breaks
  it (a mirror image reverses the order of bearings, so it is a weaker ambiguity).
* ``twin_offices``: two identical offices off one corridor; only the corridor's two
  ends differ. The walk starts inside Office 1.
* ``door_corridor``: a 40 m corridor with a door every 4 m on each side (staggered);
  only an extinguisher, a plant and the two ends differ (the ends lie on the axis, so
  their bearings tell nothing about the position along it).
* ``two_wings``: two 25 m wings of doors and windows joined by a hall, the second a
  translated copy of the first except for one object in each wing.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.maps.check import load_map
from app.maps.model import SemanticMap, parse_map
from app.resources import bundled_maps_dir
from app.simulation.scenarios import PAPER_PATH


@dataclass(frozen=True)
class HardMap:
    """A map, a walk on it, and where a kidnapper carries the person (x, y, deg).

    The simulator walks on from the kidnap pose straight to the next waypoint, so the
    pose is chosen with that leg clear of walls.
    """

    map: SemanticMap
    path: tuple[tuple[float, float], ...]
    kidnap_pose: tuple[float, float, float]
    #: True when nothing but a few objects breaks a symmetry of the map.
    symmetric: bool
    #: When the kidnapper strikes (s).
    kidnap_at_s: float = 30.0


def _box(x0: float, y0: float, x1: float, y1: float) -> list[dict[str, float]]:
    return [
        {"x1": x0, "y1": y0, "x2": x1, "y2": y0},
        {"x1": x1, "y1": y0, "x2": x1, "y2": y1},
        {"x1": x1, "y1": y1, "x2": x0, "y2": y1},
        {"x1": x0, "y1": y1, "x2": x0, "y2": y0},
    ]


def _wall(x1: float, y1: float, x2: float, y2: float) -> dict[str, float]:
    return {"x1": x1, "y1": y1, "x2": x2, "y2": y2}


def _obj(cls: str, x: float, y: float, label: str | None = None) -> dict[str, object]:
    out: dict[str, object] = {"class": cls, "x": x, "y": y}
    if label:
        out["label"] = label
    return out


def rotation_room() -> HardMap:
    objects = [_obj("window", x, y) for x in (3.0, 6.0, 9.0) for y in (0.0, 8.0)]
    # Tables in pairs that map onto each other under (x, y) -> (12 - x, 8 - y).
    objects += [_obj("table", *p) for p in ((4.0, 2.5), (8.0, 5.5), (8.5, 2.0), (3.5, 6.0))]
    objects.append(_obj("door", 12.0, 6.0, "the only door"))
    spec = {
        "name": "rotation_room",
        "walls": _box(0.0, 0.0, 12.0, 8.0),
        "objects": objects,
        "regions": [{"name": "Open office", "polygon": [[0, 0], [12, 0], [12, 8], [0, 8]]}],
    }
    path = ((10.0, 2.0), (2.0, 2.0), (2.0, 6.0), (10.0, 6.0), (10.0, 3.0), (5.0, 4.0))
    return HardMap(parse_map(spec), path, (4.0, 5.0, 0.0), True)


def symmetric_room() -> HardMap:
    """The rotation room without its door: nothing breaks the half-turn symmetry, so only
    a compass can tell the two ways round apart."""
    room = rotation_room()
    spec = room.map.to_json()
    spec["name"] = "symmetric_room"
    objects: list[dict[str, object]] = spec["objects"]  # type: ignore[assignment]  # JSON of a MapFile
    spec["objects"] = [o for o in objects if o["class"] != "door"]
    return HardMap(parse_map(spec), room.path, room.kidnap_pose, True)


def mirror_room() -> HardMap:
    objects = [_obj("window", x, 8.0) for x in (2.0, 6.0, 10.0)]
    objects += [_obj("window", x, 0.0) for x in (3.0, 9.0)]
    objects += [_obj("table", *p) for p in ((3.0, 3.0), (9.0, 3.0), (4.5, 5.5), (7.5, 5.5))]
    objects.append(_obj("door", 0.0, 2.0, "the only door"))
    spec = {
        "name": "mirror_room",
        "walls": _box(0.0, 0.0, 12.0, 8.0),
        "objects": objects,
        "regions": [{"name": "Meeting room", "polygon": [[0, 0], [12, 0], [12, 8], [0, 8]]}],
    }
    path = ((10.0, 4.0), (2.5, 4.0), (2.5, 6.5), (10.0, 6.5), (10.0, 1.5), (6.0, 1.5))
    return HardMap(parse_map(spec), path, (3.0, 1.5, 90.0), True)


def twin_offices() -> HardMap:
    walls = [
        _wall(0.0, 0.0, 22.0, 0.0),
        _wall(0.0, 0.0, 0.0, 2.5),
        _wall(22.0, 0.0, 22.0, 2.5),
        # corridor's north wall with a 1 m doorway into each office
        _wall(0.0, 2.5, 4.5, 2.5),
        _wall(5.5, 2.5, 16.5, 2.5),
        _wall(17.5, 2.5, 22.0, 2.5),
    ]
    objects = []
    for k, dx in enumerate((0.0, 12.0)):
        walls += [
            _wall(1.0 + dx, 2.5, 1.0 + dx, 9.0),
            _wall(1.0 + dx, 9.0, 9.0 + dx, 9.0),
            _wall(9.0 + dx, 9.0, 9.0 + dx, 2.5),
        ]
        objects += [
            _obj("door", 5.0 + dx, 2.5, f"Office {k + 1} door"),
            _obj("window", 3.0 + dx, 9.0),
            _obj("window", 7.0 + dx, 9.0),
            _obj("table", 3.0 + dx, 5.0),
            _obj("table", 7.0 + dx, 6.5),
            _obj("plant", 8.3 + dx, 3.2),
            _obj("window", 2.0 + dx, 0.0),
            _obj("window", 8.0 + dx, 0.0),
        ]
    objects += [_obj("door", 22.0, 1.25, "exit"), _obj("extinguisher", 0.0, 1.25)]
    spec = {
        "name": "twin_offices",
        "walls": walls,
        "objects": objects,
        "regions": [
            {"name": "Office 1", "polygon": [[1, 2.5], [9, 2.5], [9, 9], [1, 9]]},
            {"name": "Office 2", "polygon": [[13, 2.5], [21, 2.5], [21, 9], [13, 9]]},
            {"name": "Corridor", "polygon": [[0, 0], [22, 0], [22, 2.5], [0, 2.5]]},
        ],
    }
    path = (
        (3.0, 7.5),
        (7.0, 7.5),
        (7.0, 4.0),
        (5.0, 4.0),
        (5.0, 1.2),
        (17.0, 1.2),
        (17.0, 4.5),
        (19.0, 5.5),
    )
    return HardMap(parse_map(spec), path, (16.0, 6.0, -90.0), True)


def door_corridor() -> HardMap:
    length, width = 40.0, 2.2
    objects = [_obj("door", x, width) for x in range(2, 40, 4)]
    objects += [_obj("door", x, 0.0) for x in range(4, 40, 4)]
    objects += [_obj("window", 0.0, width / 2), _obj("exit", length, width / 2)]
    # Two things off the corridor's axis that tell places apart when passed (its ends
    # do not: from anywhere on the axis they lie straight ahead or straight behind).
    objects += [_obj("extinguisher", 11.0, 0.0), _obj("plant", 27.0, width)]
    spec = {
        "name": "door_corridor",
        "walls": _box(0.0, 0.0, length, width),
        "objects": objects,
        "regions": [{"name": "Corridor", "polygon": [[0, 0], [40, 0], [40, 2.2], [0, 2.2]]}],
    }
    path = ((3.0, 1.1), (33.0, 1.1))
    return HardMap(parse_map(spec), path, (20.0, 1.1, 180.0), True)


def two_wings() -> HardMap:
    walls = [
        _wall(0.0, 0.0, 28.0, 0.0),
        _wall(0.0, 12.2, 28.0, 12.2),
        _wall(0.0, 0.0, 0.0, 12.2),
        _wall(28.0, 0.0, 28.0, 2.2),
        _wall(28.0, 10.0, 28.0, 12.2),
        _wall(3.0, 2.2, 28.0, 2.2),
        _wall(3.0, 10.0, 28.0, 10.0),
        _wall(3.0, 2.2, 3.0, 10.0),
    ]
    objects = []
    for wing, dy in (("A", 0.0), ("B", 10.0)):
        doors = (6, 10, 14, 18, 22, 26)
        objects += [_obj("door", float(x), 2.2 + dy, f"Wing {wing} room {x}") for x in doors]
        objects += [_obj("window", float(x), dy) for x in (5, 9, 13, 17, 21, 25)]
    objects += [
        _obj("bench", 12.0, 0.3),  # only in wing A
        _obj("printer", 20.0, 12.0),  # only in wing B
        _obj("stairs", 0.0, 6.1),
        _obj("elevator", 1.5, 12.2),
    ]
    spec = {
        "name": "two_wings",
        "walls": walls,
        "objects": objects,
        "regions": [
            {"name": "Hall", "polygon": [[0, 0], [3, 0], [3, 12.2], [0, 12.2]]},
            {"name": "Wing A", "polygon": [[3, 0], [28, 0], [28, 2.2], [3, 2.2]]},
            {"name": "Wing B", "polygon": [[3, 10], [28, 10], [28, 12.2], [3, 12.2]]},
        ],
    }
    path = ((25.0, 1.1), (5.0, 1.1), (1.5, 1.1), (1.5, 6.0))
    return HardMap(parse_map(spec), path, (21.0, 1.1, 180.0), True)


def paper_office() -> HardMap:
    semantic_map = load_map(bundled_maps_dir() / "paper_office.json")
    return HardMap(semantic_map, PAPER_PATH, (8.5, 5.0, 180.0), False)


#: The bundled floor of the building suite (``--suite building``), its walk (x on the
#: corridor walls y = 11 and y = 13 are the doorways of the rooms visited) and its kidnap:
#: walking the east corridor at this time, carried to the west corridor.
BUILDING_MAP_NAME = "two_wing_office"
BUILDING_WALK: tuple[tuple[float, float], ...] = (
    (3.0, 12.0),  # west corridor: global start
    (6.667, 12.0),
    (6.667, 15.5),  # meeting room Rhine
    (8.5, 16.5),
    (6.667, 15.5),
    (6.667, 12.0),
    (10.333, 12.0),
    (10.333, 8.5),  # office W2
    (10.333, 12.0),
    (19.0, 12.0),  # lobby
    (19.0, 6.0),
    (19.0, 12.0),
    (27.667, 12.0),  # east corridor
    (27.667, 16.0),  # office E2
    (27.667, 12.0),
    (31.333, 12.0),
    (31.333, 8.0),  # print room
    (31.333, 12.0),
    (35.0, 12.0),
)
BUILDING_KIDNAP_AT_S = 112.0
BUILDING_KIDNAP_POSE = (4.0, 12.0, 0.0)


def building_floor() -> HardMap:
    """The bundled two-wing office floor with the building suite's walk and kidnap."""
    semantic_map = load_map(bundled_maps_dir() / f"{BUILDING_MAP_NAME}.json")
    return HardMap(semantic_map, BUILDING_WALK, BUILDING_KIDNAP_POSE, False, BUILDING_KIDNAP_AT_S)


BUILDERS = {
    "paper_office": paper_office,
    "rotation_room": rotation_room,
    "symmetric_room": symmetric_room,
    "mirror_room": mirror_room,
    "twin_offices": twin_offices,
    "door_corridor": door_corridor,
    "two_wings": two_wings,
    "two_wing_office": building_floor,
}

_CACHE: dict[str, HardMap] = {}


def hard_map(name: str) -> HardMap:
    """One of :data:`BUILDERS` (built once per process)."""
    if name not in _CACHE:
        if name not in BUILDERS:
            raise ValueError(f"unknown integrity map {name!r}: use one of {sorted(BUILDERS)}")
        _CACHE[name] = BUILDERS[name]()
    return _CACHE[name]
