"""Service settings: one pydantic-settings class, so flags and BEARINGS_* variables agree."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Annotated
from urllib.parse import urlsplit

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict


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
    store: str = Field(
        "memory",
        description="where sessions live: 'memory' (this process only) or "
        "redis://HOST:PORT/DB (shared by every worker given the same URL)",
    )
    store_lease_s: float = Field(
        1.2, gt=0, description="a worker's hold on a session in a shared store (seconds)"
    )
    checkpoint_interval_s: float = Field(
        1.0, gt=0, description="seconds between checkpoints of a changed session (shared store)"
    )
    journal_gap_s: float = Field(
        0.01,  # app.service.store.JOURNAL_GAP_S (a test holds them equal)
        ge=0,
        le=1.0,
        description="least seconds between two journal writes (shared store): frames "
        "answered meanwhile are written together; 0 writes each batch at once",
    )
    max_message_bytes: int = Field(
        65_536, ge=1024, description="largest accepted request body or WebSocket message"
    )

    # Access, privacy and overload (docs/SECURITY.md).
    api_keys_file: Path | None = Field(
        None, description="file of API keys ('key' or 'name key sessions particles frames/s')"
    )
    insecure_open: bool = Field(
        False, description="allow running without API keys on a host other than loopback"
    )
    allowed_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="browser origins allowed for CORS and WebSocket (comma or JSON list); "
        "same origin only when empty",
    )
    viser_host: str = Field("127.0.0.1", description="address the viser view listens on")
    key_default_sessions: int = Field(
        10, ge=1, description="sessions of a key whose line gives no quota"
    )
    key_default_frames_per_s: float = Field(
        50.0, gt=0, description="frames per second of a key whose line gives no quota"
    )
    max_queued_frames: int = Field(
        2, ge=1, le=16, description="frames a session holds while busy; later ones are merged"
    )
    max_waiting_steps: int = Field(
        64, ge=1, description="filter steps waiting their turn before new sessions get 503"
    )
    fair_steps: bool = Field(
        True, description="filter steps take turns between keys (false: arrival order)"
    )
    demo_walk_max_s: float = Field(
        600.0, gt=0, description="a demo walk started from the view ends after this long"
    )

    @field_validator("store")
    @classmethod
    def _store_url(cls, value: str) -> str:
        if value != "memory" and urlsplit(value).scheme not in ("redis", "rediss", "unix"):
            raise ValueError(
                "store must be 'memory' or a Redis URL such as redis://localhost:6379/0"
            )
        return value

    @field_validator("allowed_origins", mode="before")
    @classmethod
    def _origins(cls, value: object) -> object:
        """A comma-separated list or a JSON list; origins are compared without a final '/'."""
        if isinstance(value, str):
            text = value.strip()
            value = json.loads(text) if text.startswith("[") else text.split(",")
        if isinstance(value, list):
            return [str(v).strip().rstrip("/") for v in value if str(v).strip()]
        return value


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings, read from the environment once."""
    return Settings()
