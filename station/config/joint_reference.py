"""``[joints.reference]``: the length reference the station's own test of the joints
reads with its dial indicator (docs/design.md, "Joints"; docs/model.md, "The
station's own joint test"), and the test's own keys of ``[joints]``.

Three kinds, each a set of faces at calibrated distances from a datum face, set at
the plunger one at a time by the operator:

- ``"gauge blocks"``: a stop clamped to the base (the datum face) and stacks of gauge
  blocks wrung onto it; the station chooses the stacks' lengths (ISO 230-2's
  irregular targets over the travel the run needs, ``[joints] station_targets`` of
  them), ``u_mm`` is a stack's expanded uncertainty;
- ``"step gauge"``: ``faces_mm``, its faces' calibrated distances from the first
  (``u_mm`` one value, or one per face);
- ``"length bar"``: ``length_mm``, its calibrated length: two faces, the stop (the
  bar out) and the bar's end (the bar in); a lead and no shape.
"""

from __future__ import annotations

import itertools
import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

#: Linear expansion of steel (gauge blocks, step gauges, length bars), 1/K.
STEEL_EXPANSION_PER_K = 11.5e-6
#: A test's approaches of each target from each side, and a gauge-block test's targets,
#: unless the config says: ISO 230-2's five approaches; eight targets over a joint's
#: travel, at least the five the standard asks for.
DEFAULT_REPEATS = 5
DEFAULT_TARGETS = 8
KINDS = ("gauge blocks", "step gauge", "length bar")


class ReferenceConfig(BaseModel):
    """The reference's kind and faces, its calibration's expanded uncertainty (95 %),
    its material's expansion, its temperature during the test (absent: assumed,
    docs/model.md) and which way the gauge's plunger points along the joint ("-":
    toward lower ρ, the datum at the low end of the travel; "+": the other way)."""

    model_config = ConfigDict(extra="forbid", validate_default=True)

    kind: Literal["gauge blocks", "step gauge", "length bar"]
    faces_mm: list[float] | None = Field(None, min_length=2, max_length=100)
    length_mm: float | None = Field(None, gt=0, allow_inf_nan=False)
    u_mm: float | list[float] = Field(description="the calibration's expanded uncertainty "
                                                  "(95 %) of a face from the datum, mm")
    expansion_per_k: float = Field(STEEL_EXPANSION_PER_K, ge=0, le=1e-4)
    temperature_c: float | None = Field(None, ge=-20, le=60, allow_inf_nan=False)
    plunger: Literal["-", "+"] = "-"

    @field_validator("u_mm")
    @classmethod
    def _u(cls, value: float | list[float]) -> float | list[float]:
        for v in [value] if isinstance(value, int | float) else value:
            if not (math.isfinite(v) and 0 <= v <= 0.1):
                raise ValueError(f"must be between 0 and 0.1 mm, got {v}")
        return value

    @model_validator(mode="after")
    def _faces(self) -> ReferenceConfig:
        if self.kind == "step gauge":
            if self.faces_mm is None or self.length_mm is not None:
                raise ValueError("a step gauge needs faces_mm (its faces' distances from "
                                 "the first), not length_mm")
            f = self.faces_mm
            if not all(math.isfinite(v) for v in f) or \
                    any(b <= a for a, b in itertools.pairwise(f)):
                raise ValueError("faces_mm: must be finite and strictly increasing")
        elif self.kind == "length bar":
            if self.length_mm is None or self.faces_mm is not None:
                raise ValueError("a length bar needs length_mm (its calibrated length), "
                                 "not faces_mm")
        elif self.faces_mm is not None or self.length_mm is not None:
            raise ValueError("gauge blocks take neither faces_mm nor length_mm: the "
                             "station chooses the stacks")
        if isinstance(self.u_mm, list):
            faces = self.faces()
            if faces is None or len(self.u_mm) != len(faces):
                raise ValueError("u_mm: one value, or one per face (a step gauge's faces)")
        return self

    def faces(self) -> list[float] | None:
        """The faces' distances from the datum face (mm; None: gauge blocks, whose
        stacks the station chooses)."""
        if self.kind == "step gauge":
            assert self.faces_mm is not None  # checked above
            return [float(v) - float(self.faces_mm[0]) for v in self.faces_mm]
        if self.kind == "length bar":
            assert self.length_mm is not None  # checked above
            return [0.0, float(self.length_mm)]
        return None

    def u95_of(self, index: int) -> float:
        """The expanded uncertainty (95 %) of face ``index`` from the datum, mm."""
        return float(self.u_mm[index] if isinstance(self.u_mm, list) else self.u_mm)
