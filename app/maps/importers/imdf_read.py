"""Read an IMDF archive (a folder or a .zip) into features projected to metres.

IMDF (OGC Community Standard 20-094, Apple's Indoor Mapping Data Format) publishes a
venue as GeoJSON FeatureCollections in WGS84, one file per feature type
(``level.geojson``, ``unit.geojson``...) beside a ``manifest.json``. Here each file
read becomes a list of features (id, shapely geometry, properties), every geometry
projected onto a local plane at the venue (azimuthal equidistant, centred on the
venue's display point; metres, x east, y north) and snapped to a 5 mm grid, so that
edges two units share, drawn from the same points, meet exactly.
"""

from __future__ import annotations

import json
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from app.maps.importers.common import MapImportError, wgs84_projector

#: Largest IMDF archive read (all its files together, uncompressed), bytes.
MAX_IMDF_BYTES = 200_000_000
#: Coordinates are snapped to this grid after projection, metres (shared edges drawn
#: with slightly different vertices become one).
GRID_M = 0.005
#: The feature files read (others, e.g. address or footprint, are not used).
FEATURE_FILES = (
    "venue",
    "level",
    "unit",
    "opening",
    "amenity",
    "fixture",
    "relationship",
    "anchor",
    "occupant",
)
_WORD = re.compile(r"[^a-z0-9_-]")


@dataclass(frozen=True)
class Feature:
    id: str
    geometry: shapely.Geometry | None
    props: dict[str, object]


# ------------------------------------------------------------------ reading
def archive_files(path: Path) -> tuple[dict[str, bytes], list[str]]:
    """The raw bytes of each feature file (and manifest.json) in a folder or a .zip, and
    the names of the other ``.geojson`` files beside level.geojson, which the import does
    not read (sorted)."""
    names = [*(f"{n}.geojson" for n in FEATURE_FILES), "manifest.json"]

    def unread(found: list[str]) -> list[str]:
        return sorted(n for n in found if n.endswith(".geojson") and n not in names)

    out: dict[str, bytes] = {}
    if path.is_dir():
        total = 0
        for name in names:
            f = path / name
            if f.is_file():
                total += f.stat().st_size
                if total > MAX_IMDF_BYTES:
                    raise MapImportError(f"{path}: larger than {MAX_IMDF_BYTES:,} bytes")
                out[name] = f.read_bytes()
        return out, unread([f.name for f in path.iterdir() if f.is_file()])
    if not path.is_file():
        raise MapImportError(f"{path}: no such folder or .zip file")
    try:
        with zipfile.ZipFile(path) as zf:
            members = {Path(i.filename).name: i for i in zf.infolist() if not i.is_dir()}
            levels = [i for i in zf.infolist() if Path(i.filename).name == "level.geojson"]
            if not levels:
                raise MapImportError(f"{path}: no level.geojson in the archive")
            folder = min((str(Path(i.filename).parent) for i in levels), key=len)
            beside = [
                Path(i.filename).name
                for i in zf.infolist()
                if not i.is_dir() and str(Path(i.filename).parent) == folder
            ]
            total = 0
            for name in names:
                info = zf.NameToInfo.get(name if folder == "." else f"{folder}/{name}")
                if info is None:
                    info = members.get(name) if folder == "." else None
                if info is None:
                    continue
                total += info.file_size
                if total > MAX_IMDF_BYTES:
                    raise MapImportError(f"{path}: larger than {MAX_IMDF_BYTES:,} bytes unpacked")
                out[name] = zf.read(info)
    except zipfile.BadZipFile as exc:
        raise MapImportError(f"{path}: not a folder or a readable .zip ({exc})") from None
    return out, unread(beside)


#: Which features' geometries are built: (feature type, properties) -> bool.
Wanted = Callable[[str, dict[str, object]], bool]


def _everything(kind: str, props: dict[str, object]) -> bool:
    return True


def features_of(raw: bytes, where: str, kind: str, wanted: Wanted = _everything) -> list[Feature]:
    """The features of one FeatureCollection file; geometries only where ``wanted``
    (a venue's thousands of pieces of furniture need none)."""
    try:
        data = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MapImportError(f"{where}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("type") != "FeatureCollection":
        raise MapImportError(f"{where}: expected a GeoJSON FeatureCollection")
    items = data.get("features")
    if not isinstance(items, list):
        raise MapImportError(f"{where}: features: expected a list")
    out = []
    for i, feat in enumerate(items):
        at = f"{where}: features[{i}]"
        if not isinstance(feat, dict) or not isinstance(feat.get("id"), str):
            raise MapImportError(f"{at}: expected a Feature with a string id")
        if feat.get("feature_type", kind) != kind:
            raise MapImportError(
                f"{at} ({feat['id']}): feature_type {feat.get('feature_type')!r} in the "
                f"{kind} file (expected {kind!r})"
            )
        props = feat.get("properties")
        if not isinstance(props, dict):
            raise MapImportError(f"{at} ({feat['id']}): properties: expected an object")
        geom = None
        if feat.get("geometry") is not None and wanted(kind, props):
            try:
                geom = shapely.geometry.shape(feat["geometry"])
            except (ValueError, TypeError, AttributeError, KeyError) as exc:
                raise MapImportError(f"{at} ({feat['id']}): geometry: not valid ({exc})") from None
        out.append(Feature(feat["id"], geom, props))
    return out


def language_of(raw: bytes | None) -> str:
    if raw is None:
        return "en"
    try:
        manifest = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MapImportError(f"manifest.json: not valid JSON ({exc})") from None
    lang = manifest.get("language") if isinstance(manifest, dict) else None
    return lang if isinstance(lang, str) and lang else "en"


def text_of(labels: object, language: str) -> str | None:
    """A LABELS object's text in ``language`` (else English, else any), or None."""
    if isinstance(labels, str):
        return labels.strip() or None
    if not isinstance(labels, dict) or not labels:
        return None
    for key in (language, language.split("-")[0], "en"):
        if isinstance(labels.get(key), str) and labels[key].strip():
            return str(labels[key]).strip()[:200]
    first = next((v for v in labels.values() if isinstance(v, str) and v.strip()), None)
    return first.strip()[:200] if first else None


def class_word(category: object) -> str | None:
    """An object class from an IMDF category: its first word, lower case."""
    if not isinstance(category, str):
        return None
    word = _WORD.sub("", category.split(".")[0].lower())
    return word if word and word[0].isalpha() and word != "unspecified" else None


def level_id(ordinal: int) -> str:
    """The map level id of an IMDF ordinal: L0, L1, ... and B1, B2 ... below ground."""
    return f"L{ordinal}" if ordinal >= 0 else f"B{-ordinal}"


# ------------------------------------------------------------------ projection
Projector = Callable[[object], np.ndarray]


def project_all(
    features: dict[str, list[Feature]],
) -> tuple[dict[str, list[Feature]], Projector]:
    """Every geometry in metres around the venue, and the projection (for display
    points, which sit in the properties)."""
    venue = features.get("venue") or []
    centre = None
    for v in venue:
        dp = v.props.get("display_point")
        if isinstance(dp, dict) and isinstance(dp.get("coordinates"), list):
            centre = dp["coordinates"]
            break
        if v.geometry is not None:
            c = v.geometry.centroid
            centre = [c.x, c.y]
            break
    if centre is None:
        lo = [f.geometry for f in features["level"] if f.geometry is not None]
        if not lo:
            raise MapImportError("level.geojson: no level has a geometry to place the venue")
        x0, y0, x1, y1 = shapely.total_bounds(np.array(lo))
        centre = [0.5 * (x0 + x1), 0.5 * (y0 + y1)]
    try:
        lon, lat = float(centre[0]), float(centre[1])
    except (TypeError, ValueError, IndexError):
        raise MapImportError("venue.geojson: display_point is not a longitude, latitude") from None
    project = wgs84_projector((lat, lon))
    out: dict[str, list[Feature]] = {}
    for kind, feats in features.items():
        geoms = np.array([f.geometry for f in feats], dtype=object)
        has = np.array([g is not None for g in geoms], dtype=bool)
        if has.any():
            try:
                moved = shapely.transform(geoms[has], project)
            except ValueError as exc:
                raise MapImportError(f"{kind}.geojson: coordinates: {exc}") from None
            geoms[has] = shapely.set_precision(moved, GRID_M)
        out[kind] = [Feature(f.id, g, f.props) for f, g in zip(feats, geoms.tolist(), strict=True)]
    return out, project


def read_archive(
    path: Path, wanted: Wanted = _everything
) -> tuple[dict[str, list[Feature]], str, Projector, list[str]]:
    """The features of each type read (missing files give none; geometries only where
    ``wanted``), the manifest's language, the projection used, and the venue's other
    ``.geojson`` files, not read (:func:`archive_files`).

    Raises:
        MapImportError: naming the file, the feature and the reason.
    """
    files, not_read = archive_files(path)
    for required in ("level.geojson", "unit.geojson"):
        if required not in files:
            raise MapImportError(
                f"{path}: no {required} (an IMDF venue has level.geojson and unit.geojson at least)"
            )
    feats = {
        kind: features_of(files[f"{kind}.geojson"], f"{path}/{kind}.geojson", kind, wanted)
        if f"{kind}.geojson" in files
        else []
        for kind in FEATURE_FILES
    }
    language = language_of(files.get("manifest.json"))
    projected, project = project_all(feats)
    return projected, language, project, not_read
