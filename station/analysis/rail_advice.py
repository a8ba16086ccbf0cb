"""What to do about the axes' layout, in words: each axis that leans (shim its rail),
each pair of axes that pass each other (move a rail across), or, where the layout
explains the data no better than the legs' bows do, nothing on the rails
(docs/design.md, "accuracy")."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import orthocal
from station.record.result_accuracy import SquarenessDecision


class LayoutReading(Protocol):
    """What the advice reads of the pooled layout (accuracy_statement.LayoutReading)."""

    @property
    def dof(self) -> float | None: ...
    def as_dict(self) -> Mapping[str, float]: ...
    def std_errors(self) -> Mapping[str, float]: ...
    def gaps(self) -> Mapping[str, float] | None: ...
    def gap_std_errors(self) -> Mapping[str, float] | None: ...

_LEANS = {"tilt_yx": ("y", "x"), "tilt_zx": ("z", "x"), "tilt_zy": ("z", "y")}


def squareness_advice(tilts: LayoutReading | None, rail_mm: float,
                      decision: SquarenessDecision | None) -> list[str]:
    """What to do about each axis that leans (``decision``: squareness_decision's; the tilts, the
    axes' own: the squareness of the tool's motions also holds what the offsets
    written shear them by): shim the rail (tilt × its travel) or compensate in the
    controller's kinematics (model.json holds the machine)."""
    if tilts is None:
        return ["the tilts were not identified: squareness not stated"]
    k = orthocal.coverage_factor(tilts.dof)
    k_decide = None if decision is None else decision.k
    out = []
    for (name, value), se in zip(tilts.as_dict().items(), tilts.std_errors().values(),
                                 strict=True):
        axis, toward = _LEANS[name]
        if k_decide is None or abs(value) <= k_decide * se:
            why = "the model test kept no tilt" if k_decide is None else \
                f"not beyond {k_decide:.2f} standard errors"
            out.append(f"axis {axis} toward {toward} ({name}): {value:+.3f} ± {k * se:.3f} "
                       f"mm/m (95 %), {why}: nothing to do")
            continue
        shim = abs(value) * rail_mm / 1000.0
        out.append(f"axis {axis} leans {'toward +' if value > 0 else 'away from +'}{toward} "
                   f"by {abs(value):.3f} ± {k * se:.3f} mm/m ({name}): offsets cannot fix "
                   f"it; shim its rail by {1000 * shim:.0f} µm over its {rail_mm:g} mm of "
                   "travel, or put the geometry into the controller (orthocal export "
                   "--kinematics, or orthocal compensate)")
    return out


def undecided_advice(other: str) -> list[str]:
    """The advice where the axes' tilts and gaps cannot be told from the legs' bows
    (``other``: the bows' model): none on the rails, and what would tell them apart."""
    return [f"the axes' tilts and gaps found here explain the deviations no better than "
            f"the legs' bows within the stated straightness do ({other}; at the legs' "
            "middles a uniform bow is a tilt): shim or move no rail on these figures; read "
            "a second gauge plane ([[setups]] again with at = 0.75), or, if the legs are "
            "straighter than stated, their measured straightness, and calibrate again"]


_PASSES = {"gap_xy": ("x", "y", "z"), "gap_xz": ("x", "z", "y"), "gap_yz": ("y", "z", "x")}


def gap_advice(layout: LayoutReading | None, decision: SquarenessDecision | None) -> list[str]:
    """What to do about each pair of axes that pass each other (the gaps' rule is the
    tilts', ``decision``): offsets cannot fix a gap; the controller's kinematics can
    (model.json holds the machine), and so can moving a rail across by the gap."""
    gaps = None if layout is None else layout.gaps()
    if layout is None or not gaps:
        return ["the gaps between the axes were not identified: not stated"]
    se = layout.gap_std_errors() or {}
    k = orthocal.coverage_factor(layout.dof)
    k_decide = None if decision is None else decision.k
    out = []
    for name, value in gaps.items():
        a, b, along = _PASSES[name]
        if k_decide is None or abs(value) <= k_decide * se[name]:
            why = "the model test kept no gap" if k_decide is None else \
                f"not beyond {k_decide:.2f} standard errors"
            out.append(f"axes {a} and {b} ({name}): {1000 * value:+.1f} ± "
                       f"{1000 * k * se[name]:.1f} µm (95 %), {why}: nothing to do")
            continue
        out.append(f"axis {a} passes axis {b} {1000 * abs(value):.0f} ± "
                   f"{1000 * k * se[name]:.0f} µm {'above' if value > 0 else 'below'} it "
                   f"along {along} ({name}): offsets cannot fix it; put the geometry into "
                   "the controller (orthocal export --kinematics, or orthocal compensate), or "
                   "move a rail across by the gap")
    return out
