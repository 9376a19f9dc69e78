"""Schemathesis hooks for tests/api/test_fuzz.py (loaded through SCHEMATHESIS_HOOKS).

One rule of the API cannot be written in JSON Schema, which compares a number only with
constants: a pinhole camera's principal point ``cx_px`` must lie within its own image
(0 .. ``width_px``). Bodies that break it are left out of generation, so the fuzzer does
not report the 422 that rightly refuses them as "valid data rejected"; every other rule
is in the schema and checked.
"""

from __future__ import annotations

from typing import Any

import schemathesis


def _camera_within_image(camera: Any) -> bool:
    if not isinstance(camera, dict) or camera.get("model") != "pinhole":
        return True
    cx, width = camera.get("cx_px"), camera.get("width_px")
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (cx, width))
    return not numbers or 0 <= cx <= width


@schemathesis.hook
def filter_body(ctx: Any, body: Any) -> bool:
    return not isinstance(body, dict) or _camera_within_image(body.get("camera"))
