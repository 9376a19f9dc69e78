"""Service settings: one pydantic-settings class, so flags and BEARINGS_* variables agree."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    """Every setting of the service; each has a ``BEARINGS_<NAME>`` environment variable."""

    model_config = SettingsConfigDict(env_prefix="BEARINGS_", extra="ignore")

    host: str = Field("127.0.0.1", description="address the HTTP API listens on")
    port: int = Field(8000, ge=0, le=65535, description="HTTP API port")
    maps: list[Path] = Field(
        default_factory=list, description="extra map directories, besides the bundled maps/"
    )
    cache_dir: Path | None = Field(
        default_factory=lambda: Path.home() / ".cache" / "bearings",
        description="where prepared map grids are cached by content hash (none: no cache)",
    )
    viser: bool = Field(True, description="run the viser view in the same process")
    viser_port: int = Field(8080, ge=0, le=65535, description="viser view port")
    log_level: str = Field("info", description="log level: debug, info, warning, error")

    max_sessions: int = Field(100, ge=1, description="most sessions alive at once")
    session_idle_timeout_s: float = Field(
        600.0, gt=0, description="a session idle this long (seconds) is removed"
    )
    default_particles: int = Field(10_000, ge=100, description="particles when not asked")
    max_particles: int = Field(100_000, ge=100, description="most particles per session")
    max_detections: int = Field(200, ge=1, description="most detections in one frame")
    max_message_bytes: int = Field(
        65_536, ge=1024, description="largest accepted request body or WebSocket message"
    )


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings, read from the environment once."""
    return Settings()
