"""What an IMDF import made of what: the summary ``bearings map import --imdf`` prints."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

from app.maps.importers.imdf_connectors import ConnectorReport


@dataclass
class ImdfSummary:
    """What the import made of what (printed by ``bearings map import --imdf``)."""

    source: str
    levels: list[str] = field(default_factory=list)
    imdf_levels: int = 0
    units: int = 0
    walls: int = 0
    gaps: int = 0
    regions: int = 0
    unit_objects: Counter[str] = field(default_factory=Counter)
    openings: int = 0
    doors: int = 0
    outer_doors: int = 0
    amenities: int = 0
    amenity_objects: Counter[str] = field(default_factory=Counter)
    amenities_not_used: Counter[str] = field(default_factory=Counter)
    fixtures: int = 0
    fixture_walls: Counter[str] = field(default_factory=Counter)
    fixtures_not_used: Counter[str] = field(default_factory=Counter)
    relationships: int = 0
    connectors: Counter[str] = field(default_factory=Counter)
    report: ConnectorReport = field(default_factory=ConnectorReport)
    snapped: int = 0
    #: Other .geojson files of the venue, not read (feature types the import has no use
    #: for, or a tool's own files).
    not_read: list[str] = field(default_factory=list)
    #: Features that reused an id an earlier feature had (imdf_connectors.Places).
    shared_ids: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        def counts(c: Mapping[str, int]) -> str:
            return ", ".join(f"{k} {v}" for k, v in sorted(c.items())) or "none"

        r = self.report
        return [
            f"{self.source}: {len(self.levels)} levels from {self.imdf_levels} IMDF levels "
            f"({', '.join(self.levels)})",
            f"  units: {self.units} -> {self.walls} walls ({self.gaps} gaps cut at openings), "
            f"{self.regions} regions (named units), objects: {counts(self.unit_objects)}",
            f"  openings: {self.openings} -> {self.doors} doors ({self.outer_doors} in the "
            "outer wall, kept mounted in it)"
            + (
                f", {self.openings - self.doors} an elevator's (an elevator object each)"
                if self.openings > self.doors
                else ""
            ),
            f"  amenities: {self.amenities} -> objects: {counts(self.amenity_objects)}; "
            f"not used: {counts(self.amenities_not_used)}",
            f"  fixtures: {self.fixtures} -> as walls: {counts(self.fixture_walls)}; "
            f"not used: {counts(self.fixtures_not_used)}",
            f"  connectors: {counts(self.connectors)} ({r.from_relationships} from "
            f"{self.relationships} relationships, {r.by_overlap} by overlapping units); "
            f"not used: {counts(r.not_used)}",
            f"  {self.snapped} objects moved onto a wall of their level",
            *[f"  check: {line}" for line in r.skipping],
            *([self._shared_line()] if self.shared_ids else []),
            *([f"  files not read: {', '.join(self.not_read)}"] if self.not_read else []),
        ]

    def _shared_line(self) -> str:
        """The features that reused an id, the first three named."""
        named = "; ".join(self.shared_ids[:3])
        more = len(self.shared_ids) - 3
        return (
            "  ids used twice (IMDF ids are unique; the feature read first keeps it, the "
            f"other is no connector's stop): {named}" + (f"; and {more} more" if more > 0 else "")
        )
