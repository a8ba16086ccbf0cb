"""What a setup's mounting asks of the operator, as numbers: where along the leg the
stand goes and how far off it may be, which bar and which face each plunger touches,
what its reading's sign means and how far to push it in. The mount prompt says it in
words (station.console.operator) and the mounting's picture draws it
(station.report.mounting_picture); both from this one description.

The conventions (docs/design.md, "Mounting pictures"), as the simulator and the plan
check compute a reading (drivers.sim.station.VirtualStation.source,
station.plan.checker.MotionChecker.nominal_travel): a gauge along ``d`` ("y", or "-y"
for a reversed mount) reads sign(d)·(the leg's coordinate along that axis where it
crosses the gauge plane), zeroed at Π0, and a reading rises as the plunger is pushed
in. So its plunger is pushed in as the leg moves toward +d: the gauge stands on the
leg's +d side and its plunger, pointing −d, touches the leg's +d face. A reversed
mount ("-y") stands on the −y side, touching the −y face, and reads + as the leg
moves −y. The plane is base-fixed at the fraction ``at`` of the leg from its
carriage's joint at Π0 (docs/model.md, "The second gauge plane"): at·L from the
carriage's joint along the leg, (1 − at)·L from the end point's.
"""

from __future__ import annotations

from dataclasses import dataclass

from orthocal import AXES
from orthocal.postures import MIDDLE
from station.config import StationConfig
from station.plan.steps import Plan, SetupPlan


def window(stroke: float, margin: float, travel: tuple[float, float]) -> tuple[float, float]:
    """The preload (mm pushed in at mounting) that keeps ``travel`` (min, max, from the
    mounting point, + pushed in) inside the stroke less ``margin`` at both ends."""
    return margin - travel[0], stroke - margin - travel[1]


def travel_key(name: str, sp: SetupPlan) -> str:
    """The plan check's key of gauge ``name``'s travel on ``sp`` (Plan.travel)."""
    return f"{name} on leg {sp.leg} (setup {sp.index + 1})"


def cross_axes(leg: str) -> tuple[str, str]:
    """The two axes across ``leg``, in the cyclic order (x: y, z; y: z, x; z: x, y):
    seen from the carriage, looking along −leg toward the end point, the first points
    right and the second up (a right-handed view for every leg)."""
    i = AXES.index(leg)
    return AXES[(i + 1) % 3], AXES[(i + 2) % 3]


def signed(axis: str, sign: int) -> str:
    """"+y" or "−y" (the minus sign U+2212, as the operator reads it)."""
    return ("+" if sign > 0 else "\u2212") + axis


@dataclass(frozen=True)
class GaugeMount:
    """One gauge of a mounting: its name, its direction as configured ("y", "-z"),
    its plunger's stroke, the preload the config aims at, and the window of preload
    (least, most; mm pushed in) the plan check allows (None: the plan is not checked)."""

    name: str
    direction: str
    stroke_mm: float
    preload_mm: float
    window_mm: tuple[float, float] | None

    @property
    def axis(self) -> str:
        return self.direction.lstrip("-")

    @property
    def sign(self) -> int:
        """+1 along the axis, −1 for a reversed mount."""
        return -1 if self.direction.startswith("-") else 1

    @property
    def reversed(self) -> bool:
        return self.sign < 0

    @property
    def face(self) -> str:
        """The leg's face the plunger touches, the side the gauge stands on: "+y"."""
        return signed(self.axis, self.sign)

    @property
    def pointing(self) -> str:
        """Where the plunger points, from the gauge onto the leg: "−y"."""
        return signed(self.axis, -self.sign)


@dataclass(frozen=True)
class MountingSheet:
    """A setup's mounting: the leg, the gauge plane (``at``, the fraction of the leg
    from its carriage's joint at Π0), the leg's length L, the stand's tolerance along
    the leg (± ``[procedure] stand_tolerance_mm``) and the gauges."""

    setup: int  # the plan's index, 0-based
    leg: str
    at: float
    leg_length_mm: float
    tolerance_mm: float
    gauges: tuple[GaugeMount, ...]

    @property
    def file_name(self) -> str:
        """The picture's file in the run directory: mounting-1-leg-x.svg."""
        return f"mounting-{self.setup + 1}-leg-{self.leg}.svg"

    @property
    def from_carriage_mm(self) -> float:
        """The gauge plane's distance from the carriage's joint, along the leg at Π0."""
        return self.at * self.leg_length_mm

    @property
    def from_end_mm(self) -> float:
        """... and from the end point's joint."""
        return (1.0 - self.at) * self.leg_length_mm

    @property
    def middle(self) -> bool:
        return self.at == MIDDLE

    def tolerance_words(self) -> str:
        """How far off the plane the stand may stand, along the leg, in words."""
        return ("placed exactly (stand_tolerance_mm = 0)" if self.tolerance_mm <= 0 else
                f"within \u00b1{self.tolerance_mm:g} mm")

    def bar_side(self) -> dict[str, int]:
        """The side (+1/−1) of the touched bar across the leg, per cross axis: the
        gauges' side. A parallelogram's two bars are spaced along one axis across the
        leg; the plunger along that axis can reach only the nearer bar, and the other
        plunger touches that bar too, so both read one bar at one point. An axis no
        gauge measures along counts as +1 (either bar would do there)."""
        sides = {a: 1 for a in cross_axes(self.leg)}
        for g in self.gauges:
            sides[g.axis] = g.sign
        return sides


def sheet_of(config: StationConfig, plan: Plan, sp: SetupPlan) -> MountingSheet:
    """The mounting of setup ``sp``: the windows from the plan check's travel
    (``plan.travel``; None each where the plan is not checked), the strokes and
    preloads from the config's indicators, the tolerance from ``[procedure]``."""
    margin = config.procedure.plunger_margin_mm
    gauges = []
    for name, direction in sp.indicators.items():
        ind = config.indicator(name)
        travel = plan.travel.get(travel_key(name, sp))
        gauges.append(GaugeMount(name, direction, ind.stroke_mm, ind.preload,
                                 None if travel is None else
                                 window(ind.stroke_mm, margin, travel)))
    return MountingSheet(sp.index, sp.leg, sp.at, config.machine.leg_length,
                         config.procedure.stand_tolerance_mm, tuple(gauges))


def sheets_of(config: StationConfig, plan: Plan) -> list[MountingSheet]:
    """Every setup's mounting, in the plan's order."""
    return [sheet_of(config, plan, sp) for sp in plan.setups]
