"""The static part of the scene: walls, objects, labels, regions, and a top-down camera."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import viser

from app.maps.model import SemanticMap

#: Colours per class (RGB 0-255); unknown classes cycle through the palette.
CLASS_COLOURS: dict[str, tuple[int, int, int]] = {
    "door": (214, 39, 40),
    "window": (31, 119, 180),
    "table": (140, 86, 75),
}
PALETTE = [(44, 160, 44), (148, 103, 189), (255, 127, 14), (227, 119, 194), (23, 190, 207)]
WALL_COLOUR = (40, 40, 40)


def class_colour(cls: str, classes: tuple[str, ...]) -> tuple[int, int, int]:
    if cls in CLASS_COLOURS:
        return CLASS_COLOURS[cls]
    return PALETTE[classes.index(cls) % len(PALETTE)] if cls in classes else PALETTE[0]


@dataclass
class MapScene:
    """Handles of one map's static scene (remove them to switch maps)."""

    map_name: str
    walls: viser.LineSegmentsHandle | None
    objects: list[viser.PointCloudHandle]
    labels: list[viser.LabelHandle]
    camera_position: tuple[float, float, float]
    camera_look_at: tuple[float, float, float]

    def remove(self) -> None:
        for h in [self.walls, *self.objects, *self.labels]:
            if h is not None:
                h.remove()


def top_down_camera(
    semantic_map: SemanticMap, fov_rad: float = np.radians(75.0)
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Camera position and look-at point that frame the whole map from above."""
    x0, y0, x1, y1 = semantic_map.bounds
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    half = max(x1 - x0, y1 - y0) / 2 + 0.5
    height = half / np.tan(fov_rad / 2) * 1.15
    return (cx, cy - 0.01 * half, float(height)), (cx, cy, 0.0)


def build_map_scene(server: viser.ViserServer, semantic_map: SemanticMap) -> MapScene:
    """Draw the map and point the initial camera straight down on it."""
    scene = server.scene
    walls = None
    if semantic_map.walls.shape[0]:
        seg = np.zeros((semantic_map.walls.shape[0], 2, 3), dtype=np.float32)
        seg[:, 0, :2] = semantic_map.walls[:, 0:2]
        seg[:, 1, :2] = semantic_map.walls[:, 2:4]
        walls = scene.add_line_segments("/map/walls", seg, WALL_COLOUR, thickness=0.06)
    objects = []
    for cls, members in semantic_map.class_members.items():
        pts = np.zeros((members.size, 3), dtype=np.float32)
        pts[:, :2] = semantic_map.object_xy[members]
        pts[:, 2] = 0.05
        objects.append(
            scene.add_point_cloud(
                f"/map/objects/{cls}",
                pts,
                class_colour(cls, semantic_map.classes),
                point_size=0.3,
                point_shape="circle",
                precision="float32",
            )
        )
    labels = []
    for i in range(semantic_map.object_count):
        text = semantic_map.object_labels[i] or semantic_map.class_of(i)
        x, y = semantic_map.object_xy[i]
        labels.append(scene.add_label(f"/map/labels/{i}", text, position=(x, y, 0.3)))
    for r, (name, poly) in enumerate(
        zip(semantic_map.region_names, semantic_map.region_polygons, strict=True)
    ):
        cx, cy = poly.mean(axis=0)
        labels.append(scene.add_label(f"/map/regions/{r}", name, position=(cx, cy, 0.1)))
    position, look_at = top_down_camera(semantic_map)
    server.initial_camera.position = position
    server.initial_camera.look_at = look_at
    server.initial_camera.up = (0.0, 0.0, 1.0)
    return MapScene(semantic_map.name, walls, objects, labels, position, look_at)
