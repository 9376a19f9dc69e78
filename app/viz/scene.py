"""The static part of the scene: walls, objects, labels, regions, and a top-down camera.

A map with levels is drawn where the filter works, in its plane (level k ``k * pitch``
metres east of level 0, :mod:`app.maps.levels`), each level under its own node
(``/map/level-k``), and shown one level at a time: :meth:`MapScene.show_level` hides the
others and frames that level from above.
"""

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
CONNECTOR_COLOUR = (0, 150, 150)


def class_colour(cls: str, classes: tuple[str, ...]) -> tuple[int, int, int]:
    if cls in CLASS_COLOURS:
        return CLASS_COLOURS[cls]
    return PALETTE[classes.index(cls) % len(PALETTE)] if cls in classes else PALETTE[0]


Frame = tuple[tuple[float, float, float], tuple[float, float, float]]


@dataclass
class MapScene:
    """Handles of one map's static scene (remove them to switch maps)."""

    map_name: str
    walls: viser.LineSegmentsHandle | None
    objects: list[viser.PointCloudHandle]
    labels: list[viser.LabelHandle]
    camera_position: tuple[float, float, float]
    camera_look_at: tuple[float, float, float]
    #: On a map with levels: each level's group node and camera frame, and the level
    #: shown (None: the map has no levels).
    level_groups: list[viser.FrameHandle] | None = None
    level_frames: list[Frame] | None = None
    level_shown: int | None = None

    def remove(self) -> None:
        for h in [self.walls, *self.objects, *self.labels, *(self.level_groups or [])]:
            if h is not None:
                h.remove()

    def show_level(self, server: viser.ViserServer, level: int) -> None:
        """Show level ``level`` alone and frame it from above, for every viewer."""
        if self.level_groups is None or self.level_frames is None or level == self.level_shown:
            return
        for k, group in enumerate(self.level_groups):
            group.visible = k == level
        position, look_at = self.level_frames[level]
        server.initial_camera.position = position
        server.initial_camera.look_at = look_at
        for client in server.get_clients().values():
            client.camera.position = position
            client.camera.look_at = look_at
        self.level_shown = level


def top_down_camera(
    semantic_map: SemanticMap, fov_rad: float = np.radians(75.0)
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Camera position and look-at point that frame the whole map from above."""
    x0, y0, x1, y1 = semantic_map.bounds
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    half = max(x1 - x0, y1 - y0) / 2 + 0.5
    height = half / np.tan(fov_rad / 2) * 1.15
    return (cx, cy - 0.01 * half, float(height)), (cx, cy, 0.0)


def _level_frame(semantic_map: SemanticMap, level: int, fov_rad: float) -> Frame:
    """The top-down camera over one level's extent in the plane."""
    layout = semantic_map.layout
    x0, y0, x1, y1 = layout.file_bounds
    off = float(layout.offsets(level))
    cx, cy = (x0 + x1) / 2 + off, (y0 + y1) / 2
    half = max(x1 - x0, y1 - y0) / 2 + 0.5
    height = half / np.tan(fov_rad / 2) * 1.15
    return (cx, cy - 0.01 * half, float(height)), (cx, cy, 0.0)


def build_map_scene(server: viser.ViserServer, semantic_map: SemanticMap) -> MapScene:
    """Draw the map and point the initial camera straight down on it (on a map with
    levels, on its lowest level: :meth:`MapScene.show_level` moves it)."""
    if semantic_map.layout.has_levels:
        return _build_levels(server, semantic_map)
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


def _build_levels(
    server: viser.ViserServer, semantic_map: SemanticMap, fov_rad: float = np.radians(75.0)
) -> MapScene:
    """A map with levels: each level's walls, objects and labels under its own node."""
    scene = server.scene
    layout = semantic_map.layout
    groups: list[viser.FrameHandle] = []
    objects: list[viser.PointCloudHandle] = []
    labels: list[viser.LabelHandle] = []
    n_walls = len(layout.wall_level)  # the fences between levels come after: not drawn
    for lv in layout.levels:
        root = f"/map/level-{lv.index}"
        groups.append(scene.add_frame(root, show_axes=False))
        mine = np.flatnonzero(layout.wall_level == lv.index)
        if mine.size:
            seg = np.zeros((mine.size, 2, 3), dtype=np.float32)
            seg[:, 0, :2] = semantic_map.walls[:n_walls][mine, 0:2]
            seg[:, 1, :2] = semantic_map.walls[:n_walls][mine, 2:4]
            scene.add_line_segments(f"{root}/walls", seg, WALL_COLOUR, thickness=0.06)
        for cls, members in semantic_map.class_members.items():
            here = members[layout.object_level[members] == lv.index]
            if not here.size:
                continue
            pts = np.zeros((here.size, 3), dtype=np.float32)
            pts[:, :2] = semantic_map.object_xy[here]
            pts[:, 2] = 0.05
            objects.append(
                scene.add_point_cloud(
                    f"{root}/objects/{cls}",
                    pts,
                    class_colour(cls, semantic_map.classes),
                    point_size=0.3,
                    point_shape="circle",
                    precision="float32",
                )
            )
        for i in np.flatnonzero(layout.object_level == lv.index):
            text = semantic_map.object_labels[i] or semantic_map.class_of(int(i))
            x, y = semantic_map.object_xy[i]
            labels.append(scene.add_label(f"{root}/labels/{i}", text, position=(x, y, 0.3)))
        for r in np.flatnonzero(layout.region_level == lv.index):
            cx, cy = semantic_map.region_polygons[r].mean(axis=0)
            name = semantic_map.region_names[r]
            labels.append(scene.add_label(f"{root}/regions/{r}", name, position=(cx, cy, 0.1)))
        for c, conn in enumerate(layout.connectors):
            stop = conn.stop_on(lv.index)
            if stop is None:
                continue
            poly = stop.plane_polygon
            ring = np.zeros((poly.shape[0], 2, 3), dtype=np.float32)
            ring[:, 0, :2], ring[:, 1, :2] = poly, np.roll(poly, -1, axis=0)
            ring[:, :, 2] = 0.03
            scene.add_line_segments(
                f"{root}/connectors/{c}", ring, CONNECTOR_COLOUR, thickness=0.03
            )
            cx, cy = poly.mean(axis=0)
            labels.append(
                scene.add_label(
                    f"{root}/connector-labels/{c}", conn.label or conn.kind, position=(cx, cy, 0.2)
                )
            )
    frames = [_level_frame(semantic_map, lv.index, fov_rad) for lv in layout.levels]
    out = MapScene(
        semantic_map.name, None, objects, labels, frames[0][0], frames[0][1], groups, frames
    )
    out.show_level(server, 0)
    server.initial_camera.up = (0.0, 0.0, 1.0)
    return out
