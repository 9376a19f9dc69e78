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


def _number_only(value: object) -> object:
    """Refuse the values pydantic would otherwise turn into numbers: booleans, text."""
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got the boolean {str(value).lower()}")
    if isinstance(value, str | bytes | bytearray):
        raise ValueError(f"expected a number, got the string {value!r}")
    return value


#: The booleans-and-text refusal, for an integer type or a number type that needs its
#: own bounds in the annotation (a dict's values): ``Annotated[float, Field(gt=0),
#: NUMBER_ONLY]``. The validator comes after the Field: the other way round, pydantic
#: drops the bounds from the JSON schema.
NUMBER_ONLY = BeforeValidator(_number_only)
#: pydantic's strict float: an integer or a float, never a boolean or text, checked in
#: its compiled core (every number of every frame passes here; a Python validator per
#: number was a tenth of a stream's reading). :func:`problem_text` words its refusals
#: as :data:`NUMBER_ONLY` does.
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
Integer = Annotated[int, NUMBER_ONLY]


def problem_text(error: Mapping[str, Any]) -> str:
    """The message of one of pydantic's validation errors; a boolean or text refused
    where a number belongs says which it was."""
    if error.get("type") == "float_type":
        value = error.get("input")
        if isinstance(value, bool):
            return f"expected a number, got the boolean {str(value).lower()}"
        if isinstance(value, str):
            return f"expected a number, got the string {value!r}"
    return str(error.get("msg", "invalid"))


class StrictInput(BaseModel):
    """Base of every input model: unknown fields refused, aliases and names both accepted."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
