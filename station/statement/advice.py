"""The advice (docs/design.md, "The decision table"): what to do, each piece from the
decisions of the statement's quantities it rests on, its text the one every view
prints. No two contradict: the rails' advice names the controller only where the
controller's own decision says it gains, "nothing further" only where nothing acts,
and nothing on the rails where the data cannot tell the axes' tilts from the legs'
bows. The joints: their tables into the controller where a lead is decided
"compensate"; a test of the joints where the assumed bounds make most of the tool's
error."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from station.analysis.joints import positioning_input
from station.analysis.run_budget import inputs
from station.config import StationConfig
from station.record.quantity_text import plus_minus, um
from station.record.result_accuracy import DriveCount
from station.record.result_statement import CONTROLLER_ROUTES, AdviceItem, Quantity
from station.statement import decisions as rule

_LEANS = {"tilt_yx": ("y", "x", "xy"), "tilt_zx": ("z", "x", "xz"),
          "tilt_zy": ("z", "y", "yz")}
_PASSES = {"gap_xy": ("x", "y", "z"), "gap_xz": ("x", "z", "y"), "gap_yz": ("y", "z", "x")}
#: Each assumed input: its config key and how the statement's basis names its source.
_INPUTS = {"leg_straightness_mm": "leg straightness", "temperature_change_c": "temperature",
           "plunger_angle_deg": "plunger angle"}


def _controller_gains(q: Mapping[str, Quantity]) -> bool:
    c = q.get("tool.compensated.rms")
    return c is not None and c.decision == rule.GAIN


def _rails(q: Mapping[str, Quantity], rail_mm: float) -> list[AdviceItem]:
    """Shim a leaning axis, move a rail across a gap: only what acts; where the
    controller's decision gains, the geometry in the controller is the other way."""
    other = ", or put the geometry into the controller" if _controller_gains(q) else ""
    out = []
    for name, (axis, toward, pair) in _LEANS.items():
        t = q.get(name)
        if t is None or t.decision != rule.ACT or t.value is None:
            continue
        shim = abs(t.value) * rail_mm  # mrad × mm = µm
        out.append(AdviceItem(
            id=f"shim.{name}", rests_on=[name, f"squareness_{pair}"],
            text=(f"axis {axis} leans {'toward +' if t.value > 0 else 'away from +'}{toward} "
                  f"by {plus_minus(t).lstrip('+-')} ({name}), which offsets cannot fix: "
                  f"shim its rail by {shim:.0f} µm over {rail_mm:g} mm{other}")))
    for name, (a, b, along) in _PASSES.items():
        g = q.get(name)
        if g is None or g.decision != rule.ACT or g.value is None:
            continue
        out.append(AdviceItem(
            id=f"rail.{name}", rests_on=[name],
            text=(f"axis {a} passes axis {b} {'above' if g.value > 0 else 'below'} it along "
                  f"{along} by {plus_minus(g).lstrip('+-')} ({name}), which offsets cannot "
                  f"fix: move a rail across{other}")))
    return out


def _controller(q: Mapping[str, Quantity], count: DriveCount | None) -> list[AdviceItem]:
    c, a = q.get("tool.compensated.rms"), q.get("tool.after.rms")
    if c is None or a is None or c.decision != rule.GAIN:
        return []
    # the geometry's figures leave the drive's count out; where the drive counts coarsely
    # the gain is said beside what the count leaves at the tool either way (J17)
    either = "" if count is None else \
        f" (the drive's count adds {um(count.rms_mm)} µm RMS at the tool either way)"
    return [AdviceItem(
        id="controller", rests_on=[a.name, c.name],
        text=(f"put the identified geometry into the controller ({CONTROLLER_ROUTES}): the tool's "
              f"RMS error falls from {um(a.value)} to {um(c.value)} µm{either}"))]


def _plays(q: Mapping[str, Quantity]) -> list[AdviceItem]:
    """The joints' play: one piece of advice for those to compensate in the controller,
    one for those to repair (each joint's reversal with its 95 % uncertainty)."""
    out = []
    for decision, id_, what in (
            (rule.REPAIR, "repair", "repair joint(s) {joints}: a worn screw, nut or belt "
                                    "(reversal {said}); meanwhile set their backlash "
                                    "(reversal) parameter in the controller"),
            (rule.COMPENSATE, "backlash", "set the controller's backlash (reversal) "
                                          "parameter: {said}")):
        held = [r for a in "xyz" if (r := q.get(f"reversal_{a}")) is not None
                and r.decision == decision]
        if held:
            said = ", ".join(f"joint {r.name[-1]} {plus_minus(r)}" for r in held)
            out.append(AdviceItem(id=id_, rests_on=[r.name for r in held], text=what.format(
                joints=", ".join(r.name[-1] for r in held), said=said)))
    return out


#: The share of a tool figure's mean square beyond which the assumed joints "make most
#: of the tool's error" (station.statement.tool_figures.ToolFigures.assumed_share).
MOST = 0.5


def _joint_tables(q: Mapping[str, Quantity]) -> list[AdviceItem]:
    """The joints whose lead is decided "compensate": their tables into the controller."""
    held = [r for a in "xyz" if (r := q.get(f"lead_{a}")) is not None
            and r.decision == rule.COMPENSATE]
    if not held:
        return []
    return [AdviceItem(id="joint_tables", rests_on=[r.name for r in held], text=(
        f"compensate joint(s) {', '.join(r.name[-1] for r in held)} with their tables "
        "(orthocal export writes them: LinuxCNC COMP_FILE, TwinCAT lists; orthocal "
        "compensate takes them into the program): lead "
        + ", ".join(f"{r.name[-1]} {plus_minus(r)}" for r in held)))]


def _joint_tests(config: StationConfig, share: Mapping[str, float] | None,
                 assumed: Sequence[str]) -> list[AdviceItem]:
    """Where the joints without a table (``assumed``: their axes) make most of a tool
    figure's mean square (``share``): a test of those joints."""
    if not share or not assumed or max(share.values()) <= MOST:
        return []
    figure = "tool.after.rms" if share.get("after", 0.0) >= share.get("compensated", 0.0) \
        else "tool.compensated.rms"
    bound = positioning_input(config)
    value = bound.value if isinstance(bound.value, float | int) else max(bound.value)
    said = f"{'the stated' if bound.given else 'the assumed'} ±{float(value):g}"
    return [AdviceItem(id="joint_tests", rests_on=[figure], text=(
        f"give a laser test of joint(s) {', '.join(assumed)} ([joints] tests) or run the "
        f"station's own test ([joints] station_test): {said} µm/m of their positioning "
        "makes most of the tool's error"))]


def _undecided(q: Mapping[str, Quantity]) -> list[AdviceItem]:
    held = [n for n in ("tilt_yx", "tilt_zx", "tilt_zy", "gap_xy", "gap_xz", "gap_yz")
            if n in q and q[n].decision == rule.UNDECIDED]
    if not held:
        return []
    return [AdviceItem(id="undecided.layout", rests_on=held, text=(
        "shim or move no rail: the axes' tilts found here explain the deviations no "
        "better than the legs' bows within the stated straightness (at the legs' middles "
        "a uniform bow is a tilt); read a second gauge plane ([[setups]] again with at = "
        "0.75), or state the legs' measured straightness, and calibrate again"))]


def _limited_by(q: Quantity) -> str | None:
    """The Type B source that makes most of a quantity's uncertainty, if any."""
    for line in q.basis:
        name = line.split(":", 1)[0]
        return None if name == "repeatability" else name
    return None


def _inputs(config: StationConfig, q: Mapping[str, Quantity],
            undecided_type_b: list[str]) -> list[AdviceItem]:
    """State an assumed input where it, not the data, keeps a quantity undecided."""
    given = inputs(config)
    assumed = {src: key for key, src in _INPUTS.items()
               if not getattr(given, key).given}
    hit: dict[str, list[str]] = {}
    for name in undecided_type_b:
        src = _limited_by(q[name])
        if src in assumed:
            hit.setdefault(assumed[src], []).append(name)
    out = []
    for key, names in hit.items():
        value = getattr(given, key).value
        out.append(AdviceItem(id=f"state.{key}", rests_on=names, text=(
            f"state [uncertainty] {key} (measured; {value} assumed): it, not the data, keeps "
            f"{', '.join(names)} from being decided")))
    return out


def advice(config: StationConfig, quantities: list[Quantity], undecided_type_b: list[str],
           converged: bool, remedy: str | None,
           joints_share: Mapping[str, float] | None = None,
           assumed_joints: Sequence[str] = (),
           drive_count: DriveCount | None = None) -> list[AdviceItem]:
    """Every piece of advice for the statement's ``quantities`` (module docstring);
    ``undecided_type_b``: the quantities the stated inputs alone keep undecided
    (station.statement.conclude), ``remedy``: what would let an unconverged loop
    converge (the verdict's words); ``joints_share``: the assumed joints' share of the
    tool's figures (station.statement.tool_figures.ToolFigures.assumed_share) and
    ``assumed_joints`` those joints; ``drive_count``: what the drive's count does at the
    tool (accuracy.drive_count), which the geometry's figures leave out."""
    q = {x.name: x for x in quantities}
    rail_mm = config.machine.rho_max - config.machine.rho_min
    out = _undecided(q) or _rails(q, rail_mm)
    out += _controller(q, drive_count) + _joint_tables(q) + _plays(q)
    out += _joint_tests(config, joints_share, assumed_joints)
    out += _inputs(config, q, undecided_type_b)
    if remedy:
        out.append(AdviceItem(id="converge", rests_on=[n for n in q if n.endswith(".as_left")],
                              text=remedy))
    if not out and converged:
        out.append(AdviceItem(id="nothing", rests_on=sorted(q),
                              text="nothing further: nothing else stands out of the noise"))
    return out
