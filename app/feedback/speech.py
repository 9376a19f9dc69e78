"""Offline speech with espeak-ng: text in, WAV bytes out."""

from __future__ import annotations

import shutil
import subprocess

MAX_CHARS = 2000


class SpeechUnavailable(RuntimeError):
    """No speech engine is installed (or it failed); the message says what to do."""


def synthesize_wav(text: str, *, rate_wpm: int = 160, voice: str = "en") -> bytes:
    """Speak ``text`` with espeak-ng and return the WAV file's bytes.

    Raises:
        ValueError: for empty or overlong text.
        SpeechUnavailable: when espeak-ng is missing or fails.
    """
    if not text.strip():
        raise ValueError("text is empty")
    if len(text) > MAX_CHARS:
        raise ValueError(f"text is longer than {MAX_CHARS} characters")
    binary = shutil.which("espeak-ng")
    if binary is None:
        raise SpeechUnavailable(
            "no speech engine: espeak-ng is not installed on the server "
            "(Debian/Ubuntu: apt-get install espeak-ng)"
        )
    try:
        # The text goes on stdin, never through a shell.
        proc = subprocess.run(
            [binary, "-v", voice, "-s", str(int(rate_wpm)), "--stdin", "--stdout"],
            input=text.encode("utf-8"),
            capture_output=True,
            timeout=20,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise SpeechUnavailable(f"espeak-ng failed to run: {exc}") from None
    if proc.returncode != 0 or not proc.stdout.startswith(b"RIFF"):
        err = proc.stderr.decode("utf-8", "replace").strip()[:200]
        raise SpeechUnavailable(f"espeak-ng failed (exit {proc.returncode}): {err}")
    return proc.stdout
