"""What every section of result.json is built from (station.record.result): a closed
model, the maps keyed by axis or parameter name, a 95 % interval, a section that
could not be stated, and the JSON value of a document read whole."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, JsonValue

Axis3 = dict[str, float | None]  # {"x": …, "y": …, "z": …}, mm
Params = dict[str, float | None]  # parameter name (docs/model.md: drho_x, tilt_yx, …) → value
Interval = tuple[float, float]  # [lo, hi] of a 95 % interval
JsonObject = dict[str, JsonValue]  # a JSON document read whole, not yet migrated


class Closed(BaseModel):
    """A section of the record: every field declared, none other accepted."""

    model_config = ConfigDict(extra="forbid")


class NotStated(Closed):
    """A section the run could not compute (``accuracy``, ``uncertainty_budget``)."""

    error: str = Field(description='"not stated: " and why')
