"""Offline speech with espeak-ng."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from app.feedback.speech import SpeechUnavailable, synthesize_wav

HAVE_ESPEAK = shutil.which("espeak-ng") is not None


@pytest.mark.skipif(not HAVE_ESPEAK and not os.environ.get("CI"), reason="espeak-ng not installed")
def test_speaks_a_real_wav() -> None:
    wav = synthesize_wav("Door at 2 o'clock, about 3 metres.")
    assert wav[:4] == b"RIFF" and wav[8:12] == b"WAVE"
    assert len(wav) > 10_000  # about a second of audio, not an empty header


def test_missing_engine_is_a_clear_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(SpeechUnavailable, match="espeak-ng is not installed"):
        synthesize_wav("hello")


@pytest.mark.parametrize("text", ["", "   ", "x" * 2001])
def test_bad_text_is_refused(text: str) -> None:
    with pytest.raises(ValueError):
        synthesize_wav(text)
