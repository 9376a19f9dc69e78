"""What each table cell runs: scenario, field of view, filter configuration, faults.

Tables I-III follow the paper's protocol (see :mod:`app.simulation.scenarios`) for
cameras of 180, 270 and 360 degrees, each in two configurations: ``paper`` (the
paper's model only) and ``bearings`` (our defaults, adaptive particle count), plus
``bearings-fixed`` (our defaults with the particle count fixed) so that the adaptive
count is judged on the same walks. Table IV goes beyond the paper: noisier bearings and
false detections, as a real detector would give.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from app.localization.config import FilterConfig
from app.simulation.scenarios import Scenario, paper_config
from app.simulation.simulator import SimulationConfig

FOVS = (180.0, 270.0, 360.0)
CONFIGS = ("paper", "bearings")
#: Our defaults without the adaptive particle count (Tables I-III only).
FIXED = "bearings-fixed"
SCENARIO_OF_TABLE: dict[str, Scenario] = {"I": "nominal", "II": "occlusion", "III": "missing"}
TABLE4_FOVS = (360.0, 180.0)
TABLE4_NOISE_DEG = (1.0, 2.0, 5.0, 10.0)
TABLE4_FALSE_RATES = (0.0, 0.5, 1.0)

#: The paper's own numbers (Tables I-III), typed from the paper for comparison.
#: Keys: (table, fov) -> (mean_m, std_m, mean_deg, std_deg).
PAPER_RESULTS: dict[tuple[str, float], tuple[float, float, float, float]] = {
    ("I", 180.0): (0.21069, 0.23469, 0.042, 0.047),
    ("I", 270.0): (0.04796, 0.03102, 0.008, 0.007),
    ("I", 360.0): (0.03316, 0.01944, 0.004, 0.003),
    ("II", 180.0): (0.57748, 0.61999, 0.038, 0.048),
    ("II", 270.0): (0.22748, 0.41747, 0.0170, 0.0278),
    ("II", 360.0): (0.05762, 0.04620, 0.004, 0.0031),
    ("III", 180.0): (0.44887, 0.48477, 0.067, 0.072),
    ("III", 270.0): (0.28283, 0.42585, 0.391, 0.060),
    ("III", 360.0): (0.07261, 0.16332, 0.007, 0.018),
}


@dataclass(frozen=True)
class Cell:
    """One table cell: a simulation setting and a filter configuration."""

    table: str
    scenario: str
    fov_deg: float
    config: str
    bearing_noise_deg: float = 2.0
    false_rate: float = 0.0

    def simulation(self) -> SimulationConfig:
        # Tables I-III simulate their own scenario; Table IV adds its faults to the nominal walk.
        base_scenario: Scenario = SCENARIO_OF_TABLE.get(self.table, "nominal")
        sim = paper_config(base_scenario, self.fov_deg)
        if self.table == "IV":
            sim = replace(sim, bearing_noise_deg=self.bearing_noise_deg, false_rate=self.false_rate)
        return sim

    def filter_config(self, particles: int) -> FilterConfig:
        # The filter is told the camera's field of view and the nominal bearing noise;
        # in Table IV it is told the true noise level too (a calibrated detector).
        std = self.bearing_noise_deg
        if self.config == "paper":
            return FilterConfig.paper(
                particles=particles, fov_deg=self.fov_deg, bearing_std_deg=std
            )
        adaptive = self.config != FIXED
        return FilterConfig(
            particles=particles, fov_deg=self.fov_deg, bearing_std_deg=std, adaptive=adaptive
        )


def cells(tables: tuple[str, ...]) -> list[Cell]:
    """Every cell of the requested tables, in a stable order."""
    out: list[Cell] = []
    for table in tables:
        if table in SCENARIO_OF_TABLE:
            for fov in FOVS:
                for cfg in (*CONFIGS, FIXED):
                    out.append(Cell(table, SCENARIO_OF_TABLE[table], fov, cfg))
        elif table == "IV":
            for fov in TABLE4_FOVS:
                for noise in TABLE4_NOISE_DEG:
                    for rate in TABLE4_FALSE_RATES:
                        for cfg in CONFIGS:
                            out.append(Cell("IV", "noisy", fov, cfg, noise, rate))
        else:
            raise ValueError(f"unknown table {table!r}: use I, II, III or IV")
    return out
