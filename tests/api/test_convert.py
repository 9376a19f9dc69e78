"""The wire shape of a step's outcome: the validated model and the stream's JSON text."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.api.convert import frame_result, frame_result_json
from app.feedback.narrator import Feedback, FeedbackItem
from app.guidance.guide import Guidance, NextTurn
from app.localization.types import Estimate, Hypothesis
from app.service.types import FrameOutcome

#: Numbers of every size and sign a result may carry (before the rounding it applies).
NUMBERS = [0.0, -0.0, 1e-9, 0.00005, 0.5, 1.0, 2.25, 123.456789, 1e6, 3e7, 1e16, -7.5e-5]
TEXTS = ["", "Door at 2 o'clock, about 3 metres.", 'Café "Lounge"\n\\ 中文 😀', "\x00\x1f\u2028"]


def outcome(rng: np.random.Generator, k: int) -> FrameOutcome:
    def number() -> float:
        v = float(rng.choice(NUMBERS)) if rng.random() < 0.3 else float(rng.normal(0, 10))
        kind = rng.random()  # numpy's scalars and whole numbers too, as code may hand over
        return np.float64(v) if kind < 0.2 else (int(v) if kind < 0.3 else v)  # type: ignore[return-value]

    def text() -> str:
        return str(rng.choice(TEXTS))

    hyps = tuple(
        Hypothesis(number(), number(), number(), abs(number()), abs(number()))
        for _ in range(int(rng.integers(0, 5)))
    )
    est = Estimate(
        number(),
        number(),
        number(),
        math.inf if k % 7 == 0 else abs(number()),
        abs(number()),
        abs(number()),
        bool(k % 2),
        hyps,
        2000,
        1000.0,
        None if k % 3 == 0 else abs(number()),
    )
    items = [
        FeedbackItem(
            text() or "door",
            None if k % 4 == 0 else text(),
            None if k % 5 == 0 else int(rng.integers(1, 13)),
            None if k % 5 == 0 else number(),
            None if k % 6 == 0 else abs(number()),
        )
        for _ in range(int(rng.integers(0, 4)))
    ]
    guidance = None
    if k % 2:
        turn = None if k % 4 == 1 else NextTurn(number(), abs(number()), number())
        path = np.zeros((2, 2))
        guidance = Guidance(
            text() or "exit", number(), abs(number()), abs(number()), turn, k % 8 == 1, path
        )
    return FrameOutcome(
        seq=k + 1,
        estimate=est,
        feedback=Feedback(text(), items),
        warnings=tuple(text() for _ in range(int(rng.integers(0, 3)))),
        regions=tuple(None if rng.random() < 0.3 else text() for _ in hyps),
        guidance=guidance,
    )


@pytest.mark.parametrize("seed", range(4))
def test_the_streams_json_is_the_models_json(seed: int) -> None:
    """Text for text, whatever the numbers (their shortest forms, signed zeros, large
    and small ones, numpy scalars, whole numbers), strings (quotes, escapes, non-ASCII)
    and missing parts."""
    rng = np.random.default_rng(seed)
    for k in range(300):
        o = outcome(rng, k)
        model = frame_result(o)
        assert frame_result_json(o) == model.model_dump_json(by_alias=True), k
        assert json.loads(frame_result_json(o))["feedback"]["items"] == [
            item.model_dump(by_alias=True) for item in model.feedback.items
        ]
