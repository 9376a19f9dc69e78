"""A small venue of three floors, made in code, for the venue suite and the tests.

Each floor is a 24 m x 14 m hall with the same shell: an elevator car in the south-west
corner (3 m x 3 m, its door on the north side), a stairwell in the south-east corner
and two escalators in the middle (one up from the Ground to the First Floor, one down
back again, each 6 m long; a stop is the escalator's footprint, the same on both
floors). The floors differ by their furniture and fittings, as real floors do,
but share the doors and windows of the shell, so what is seen right after a ride
does not settle the floor at once.
"""

from __future__ import annotations

from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import ensure_prepared
from app.simulation.venue_walk import Leg, Ride, Walk

#: The venue's name (a usable map file name).
VENUE_NAME = "three_floor_venue"
#: Level ids, names and elevations, metres.
LEVELS = (
    ("L0", "Ground Floor", 0, 0.0),
    ("L1", "First Floor", 1, 4.5),
    ("L2", "Second Floor", 2, 9.0),
)
WIDTH_M = 24.0
DEPTH_M = 14.0


def _wall(x1: float, y1: float, x2: float, y2: float, level: str) -> dict[str, object]:
    return {"x1": x1, "y1": y1, "x2": x2, "y2": y2, "level": level}


def _obj(cls: str, x: float, y: float, level: str, label: str | None = None) -> dict[str, object]:
    out: dict[str, object] = {"class": cls, "x": x, "y": y, "level": level}
    if label:
        out["label"] = label
    return out


def _square(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def _shell(level: str) -> tuple[list[dict[str, object]], list[dict[str, object]]]:
    """The walls every floor shares and the fittings in them."""
    w, d = WIDTH_M, DEPTH_M
    walls = [
        _wall(0.0, 0.0, w, 0.0, level),
        _wall(w, 0.0, w, d, level),
        _wall(w, d, 0.0, d, level),
        _wall(0.0, d, 0.0, 0.0, level),
        # the elevator car: 0..3 x 0..3, door from x 0.9 to 2.1 on its north side
        _wall(3.0, 0.0, 3.0, 3.0, level),
        _wall(0.0, 3.0, 0.9, 3.0, level),
        _wall(2.1, 3.0, 3.0, 3.0, level),
        # an office on the north side: 14..24 x 9..14, a door at x 15..16
        _wall(14.0, 9.0, 15.0, 9.0, level),
        _wall(16.0, 9.0, w, 9.0, level),
        _wall(14.0, 9.0, 14.0, d, level),
    ]
    objects = [
        _obj("elevator", 1.5, 3.0, level, "Lift A"),
        _obj("door", 15.5, 9.0, level, "Office"),
        _obj("window", 6.0, d, level),
        _obj("window", 10.0, d, level),
        _obj("window", 20.0, d, level),
        _obj("window", 8.0, 0.0, level),
        _obj("window", 14.0, 0.0, level),
        _obj("stairs", 22.0, 4.2, level, "Stairs"),
    ]
    return walls, objects


#: What differs per floor: (class, x, y, label).
FITTINGS: dict[str, tuple[tuple[str, float, float, str | None], ...]] = {
    "L0": (
        ("door", 0.0, 8.0, "Main entrance"),
        ("desk", 6.0, 6.0, "Information"),
        ("bench", 4.0, 11.0, None),
        ("plant", 12.5, 12.5, None),
        ("escalator", 9.0, 5.75, "Escalator up"),
        ("escalator", 9.0, 8.25, "Escalator down"),
        ("table", 19.0, 11.5, None),
    ),
    "L1": (
        ("sign", 0.0, 8.0, "Platforms"),
        ("bench", 5.0, 6.0, None),
        ("vending_machine", 3.5, 13.5, None),
        ("escalator", 16.0, 5.75, "Escalator up"),
        ("escalator", 16.0, 8.25, "Escalator down"),
        ("table", 18.0, 11.0, None),
        ("table", 21.0, 11.0, None),
    ),
    "L2": (
        ("sign", 0.0, 8.0, "Exit"),
        ("plant", 6.0, 12.5, None),
        ("bench", 11.0, 11.0, None),
        ("printer", 20.0, 13.5, None),
        ("desk", 12.0, 4.0, "Ticket office"),
    ),
}


#: The escalators' footprints (the same on both floors they join): 6 m long, running
#: east (up, its foot at x = 9.5 on the Ground Floor) and west (down, its foot at x = 9.5
#: on the Ground Floor too, its head at x = 15.5 on the First Floor).
ESCALATOR_UP = _square(9.5, 5.0, 15.5, 6.5)
ESCALATOR_DOWN = _square(9.5, 7.5, 15.5, 9.0)
#: The lift car's floor and the stairwell.
LIFT_STOP = _square(0.4, 0.4, 2.6, 2.6)
STAIRS_STOP = _square(20.5, 0.5, 23.5, 3.5)


def venue_spec(name: str = VENUE_NAME) -> dict[str, object]:
    """The venue's map file as JSON."""
    walls: list[dict[str, object]] = []
    objects: list[dict[str, object]] = []
    regions: list[dict[str, object]] = []
    for level, level_name, _, _ in LEVELS:
        shell_walls, shell_objects = _shell(level)
        walls += shell_walls
        objects += shell_objects
        objects += [_obj(c, x, y, level, label) for c, x, y, label in FITTINGS[level]]
        regions += [
            {"name": f"{level_name} hall", "polygon": _square(0, 0, WIDTH_M, 9.0), "level": level},
            {
                "name": f"{level_name} office",
                "polygon": _square(14, 9, WIDTH_M, DEPTH_M),
                "level": level,
            },
        ]
    lift_stop = LIFT_STOP
    stairs_stop = STAIRS_STOP
    connectors = [
        {
            "id": "lift-a",
            "kind": "elevator",
            "label": "Lift A",
            "stops": [{"level": lv[0], "polygon": lift_stop} for lv in LEVELS],
        },
        {
            "id": "stairs",
            "kind": "stairs",
            "label": "Stairs",
            "stops": [{"level": lv[0], "polygon": stairs_stop} for lv in LEVELS],
        },
        {
            "id": "esc-up",
            "kind": "escalator",
            "label": "Escalator up",
            "direction": "up",
            "stops": [
                {"level": "L0", "polygon": ESCALATOR_UP},
                {"level": "L1", "polygon": ESCALATOR_UP},
            ],
        },
        {
            "id": "esc-down",
            "kind": "escalator",
            "label": "Escalator down",
            "direction": "down",
            "stops": [
                {"level": "L1", "polygon": ESCALATOR_DOWN},
                {"level": "L0", "polygon": ESCALATOR_DOWN},
            ],
        },
    ]
    return {
        "name": name,
        "description": "A made-up venue of three floors joined by a lift, stairs and two "
        "escalators (app/simulation/venue.py).",
        "levels": [{"id": i, "name": n, "ordinal": o, "elevation_m": e} for i, n, o, e in LEVELS],
        "walls": walls,
        "objects": objects,
        "regions": regions,
        "connectors": connectors,
    }


def venue_map() -> SemanticMap:
    """The venue as a :class:`SemanticMap`, its grids prepared."""
    return ensure_prepared(parse_map(venue_spec()))


def venue_legs() -> tuple[str, list[Leg]]:
    """The venue suite's walk: its start level and legs (about 4 minutes).

    The Ground Floor's hall, the lift up two floors, the Second Floor, the stairs down
    to the First Floor, the First Floor, the escalator down, the Ground Floor, the
    escalator up, the First Floor's office.
    """
    legs: list[Leg] = [
        Walk(((6.0, 11.0), (12.0, 11.5), (12.0, 4.0), (5.0, 4.0), (1.5, 5.0), (1.5, 1.5))),
        Ride("elevator", "L2", climb_mps=1.0, wait_s=3.0),
        Walk(((1.5, 5.0), (8.0, 7.0), (14.0, 11.0), (10.0, 12.0), (18.0, 4.0), (21.0, 3.0))),
        Ride("stairs", "L1", ((21.0, 1.0), (23.0, 1.0), (23.0, 3.0)), speed_mps=0.35),
        Walk(((20.0, 6.0), (6.0, 7.0), (6.0, 11.0), (16.0, 7.0), (15.4, 8.25))),
        Ride("escalator", "L0", ((9.5, 8.25),), speed_mps=0.5),
        Walk(((6.0, 8.0), (5.0, 12.0), (12.0, 12.0), (9.6, 6.8), (9.6, 5.75))),
        Ride("escalator", "L1", ((15.5, 5.75),), speed_mps=0.5),
        Walk(((17.0, 6.0), (15.5, 8.0), (15.5, 10.5), (20.0, 11.5))),
    ]
    return "L0", legs
