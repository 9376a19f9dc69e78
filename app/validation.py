"""The strict building blocks of every input model (request bodies and map files).

One definition each, used by :mod:`app.api.schemas` and :mod:`app.maps.model`:

* :data:`Finite`: a real number, finite (no NaN or infinity). A JSON boolean or
  string is refused (``true`` or ``"1.5"`` is not read as 1 or 1.5), so a client's
  mistake surfaces as a 422 instead of a silent zero. Integers are numbers.
* :data:`Integer`: a whole number, refusing booleans and strings likewise; a JSON
  number with a zero fraction (``3.0``) is an integer, as JSON Schema says.
* Flags use pydantic's ``StrictBool`` (no ``"yes"`` or ``1`` for ``true``).
* :class:`StrictInput`: unknown fields are refused (a typo is an error, not ignored).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field


def _refusal(value: object) -> str | None:
    """Why ``value`` is no number, for a boolean or text (None for anything else)."""
    if isinstance(value, bool):
        return f"expected a number, got the boolean {str(value).lower()}"
    if isinstance(value, str | bytes | bytearray):
        return f"expected a number, got the string {value!r}"
    return None


def _number_only(value: object) -> object:
    """Refuse the values pydantic would otherwise turn into integers: booleans, text."""
    refusal = _refusal(value)
    if refusal is not None:
        raise ValueError(refusal)
    return value


#: The booleans-and-text refusal for an integer type, also one with its own bounds:
#: ``Annotated[int, Field(ge=100), NUMBER_ONLY]`` (pydantic's strict int would refuse
#: ``3.0`` too). The validator comes after the Field: the other way round, pydantic
#: drops the bounds from the JSON schema.
NUMBER_ONLY = BeforeValidator(_number_only)
#: pydantic's strict float: an integer or a float, never a boolean or text, checked in
#: its compiled core (every number of every frame passes here; a Python validator per
#: number was a tenth of a stream's reading). A number type with its own bounds adds
#: them to the same Field: ``Annotated[float, Field(gt=0, allow_inf_nan=False,
#: strict=True)]``. :func:`problem_text` words its refusals as :data:`NUMBER_ONLY` does.
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
Integer = Annotated[int, NUMBER_ONLY]


def problem_text(error: Mapping[str, Any]) -> str:
    """The message of one of pydantic's validation errors; a boolean or text refused
    where a number belongs says which it was."""
    if error.get("type") == "float_type":
        refusal = _refusal(error.get("input"))
        if refusal is not None:
            return refusal
    return str(error.get("msg", "invalid"))


class StrictInput(BaseModel):
    """Base of every input model: unknown fields refused, aliases and names both accepted."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
