"""The value types' shortcuts agree with the general forms they stand for."""

from __future__ import annotations

from dataclasses import fields, replace

from app.localization.types import Estimate, Hypothesis


def _distinct_estimate() -> Estimate:
    """An estimate whose every field holds a value no other field holds."""
    values: list[object] = []
    for k, f in enumerate(fields(Estimate)):
        if f.name == "converged":
            values.append(True)
        elif f.name == "hypotheses":
            values.append((Hypothesis(1.0, 2.0, 0.5, 0.9, 0.2),))
        else:
            values.append(float(k) + 0.25)
    return Estimate(*values)  # type: ignore[arg-type]


def test_with_converged_and_with_protection_are_replace() -> None:
    e = _distinct_estimate()
    assert e.with_converged(False) == replace(e, converged=False)
    assert e.with_converged(True) == replace(e, converged=True)
    assert e.with_protection(7.5) == replace(e, protection_m=7.5)
    assert e.with_protection(None) == replace(e, protection_m=None)
