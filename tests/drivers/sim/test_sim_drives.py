"""A simulator as varied as the drives: the virtual drive's profile
shapes, own acceleration, start delays and axis sequences; stopping any of them;
the plain "independent" drive unchanged; every move that drove a plunger past an
end of its stroke counted from the trajectory, read or not; a knocked stand; the
config that tells the station nothing of the drive's timing (the command line:
test_sim_drive_options.py).

Every look at a move mid-way uses a stepped clock: nothing depends on the host.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import orthocal
from drivers.sim.drive_motion import DriveMotion
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.specs import DriveSpec, GaugeSpec
from drivers.sim.station import VirtualStation
from station.commands.simulate.station_setups import SimulatedStation
from station.config import parse_config

GEOMETRY = orthocal.Geometry()
PI0 = orthocal.posture("0", None, GEOMETRY)
SPEED, ACCEL = 100.0, 1000.0
INDEPENDENT = DriveSpec(motion="independent", speed_mm_s=SPEED, accel_mm_s2=ACCEL)
DT = 0.0005  # the stepped clock's tick (s)
# A move of three axes: x cruises at the speed, y only just reaches it, z never does.
DELTA = np.array([40.0, -9.0, 2.5])


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def machine_with(drive: DriveMotion | str, clock: Clock, **kw: Any) -> VirtualOrthoglide:
    return VirtualOrthoglide(GEOMETRY, speed_mm_s=SPEED, accel_mm_s2=ACCEL, clock=clock,
                             motion=drive, **kw)


def follow(machine: VirtualOrthoglide, clock: Clock, target: np.ndarray,
           dt: float = DT) -> tuple[float, np.ndarray, np.ndarray, list[bool]]:
    """Start a move and step the clock through it: (duration, times, positions,
    moving flags), from the command to a little after the returned duration."""
    duration = machine.move_to(target)
    t0 = clock.t
    times, positions, moving = [], [], []
    while clock.t <= t0 + duration + 5 * dt:
        times.append(clock.t - t0)
        positions.append(machine.actual())
        moving.append(machine.status().moving)
        clock.t += dt
    return duration, np.array(times), np.array(positions), moving


DRIVES = {
    "plain": {},
    "delays": {"start_delay_s": (0.0, 0.004, 0.011)},
    "sequence zyx": {"sequence": "zyx"},
    "sequence xzy, delays": {"sequence": "xzy", "start_delay_s": (0.002, 0.0, 0.005)},
    "own accelerations": {"accel_mm_s2": (400.0, None, 3000.0)},
}


@pytest.mark.parametrize("shape", ["trapezoid", "scurve", "cosine"])
@pytest.mark.parametrize("variant", list(DRIVES))
def test_every_profile_is_monotone_within_its_box_and_speed_and_arrives(
        shape: str, variant: str) -> None:
    clock = Clock()
    drive = DriveMotion(shape=shape, **DRIVES[variant])
    machine = machine_with(drive, clock)
    start = machine.actual()
    target = start + DELTA
    duration, times, pos, moving = follow(machine, clock, target)
    assert math.isfinite(duration) and duration > 0
    step = np.diff(pos, axis=0)
    # monotone from start to target along each axis, never beyond either end
    assert np.all(step * np.sign(DELTA) >= -1e-9), np.min(step * np.sign(DELTA))
    lo, hi = np.minimum(start, target), np.maximum(start, target)
    assert np.all(pos >= lo - 1e-9) and np.all(pos <= hi + 1e-9)
    # within the commanded speed (the finite difference is a mean over one tick)
    assert np.max(np.abs(step)) / DT <= SPEED * (1 + 1e-9)
    # within each axis's acceleration (second differences, a tick's rounding allowed)
    accels = drive.accels(ACCEL)
    second = np.abs(np.diff(pos, 2, axis=0)) / DT**2
    for i in range(3):
        assert np.max(second[:, i]) <= accels[i] * 1.01 + 1e-6, (i, np.max(second[:, i]))
    # moving until the duration move_to returned, then exactly at the target
    assert all(m for t, m in zip(times, moving, strict=True) if t < duration - 1e-9)
    assert not moving[-1]
    np.testing.assert_allclose(pos[-1], target, atol=1e-9)
    status = machine.status()
    assert status.in_position and not status.moving


def test_the_shapes_are_what_they_say() -> None:
    # Over the same 40 mm at 100 mm/s and 1000 mm/s²: the S-curve takes its jerk
    # ramps longer than the trapezoid; the cosine, its peak acceleration only at the
    # ends, longer still when not speed-limited, and exactly the formula's time.
    durations = {}
    for shape in ("trapezoid", "scurve", "cosine"):
        clock = Clock()
        durations[shape] = machine_with(DriveMotion(shape=shape), clock).move_to(
            PI0 + np.array([0.0, 0.0, 2.0]))
    assert durations["trapezoid"] == pytest.approx(2 * math.sqrt(2.0 / ACCEL))
    assert durations["scurve"] > durations["trapezoid"]
    assert durations["cosine"] == pytest.approx(math.pi * math.sqrt(2.0 / (2 * ACCEL)))
    long = {}
    for shape in ("trapezoid", "cosine"):
        long[shape] = machine_with(DriveMotion(shape=shape), Clock()).move_to(
            PI0 + np.array([0.0, 0.0, 40.0]))
    assert long["cosine"] == pytest.approx(math.pi * 40.0 / (2 * SPEED))  # speed-limited
    assert long["trapezoid"] == pytest.approx(40.0 / SPEED + SPEED / ACCEL)
    # the S-curve's jerk time is a parameter: a longer ramp, a longer move
    slow = machine_with(DriveMotion(shape="scurve", jerk_time_s=0.2), Clock())
    assert slow.move_to(PI0 + np.array([0.0, 0.0, 2.0])) > durations["scurve"]


def test_a_sequence_moves_one_axis_after_another_each_after_its_delay() -> None:
    clock = Clock()
    delays = (0.003, 0.006, 0.009)
    machine = machine_with(DriveMotion(sequence="zxy", start_delay_s=delays), clock)
    start = machine.actual()
    duration, times, pos, _ = follow(machine, clock, start + DELTA)
    moved = np.abs(pos - start) > 1e-12
    arrived = np.abs(pos - (start + DELTA)) <= 1e-12
    first_move = {a: times[np.argmax(moved[:, i])] for i, a in enumerate("xyz")}
    arrival = {a: times[np.argmax(arrived[:, i])] for i, a in enumerate("xyz")}
    assert first_move["z"] >= delays[2] - DT
    assert first_move["x"] >= arrival["z"] + delays[0] - DT  # z first, then x
    assert first_move["y"] >= arrival["x"] + delays[1] - DT  # then y
    assert arrival["y"] == pytest.approx(duration, abs=2 * DT)
    # together, the same axes would be done in the longest one's time
    together = machine_with("independent", Clock()).move_to(PI0 + DELTA)
    assert duration > together + sum(delays)


@pytest.mark.parametrize("shape", ["trapezoid", "scurve", "cosine"])
def test_stop_brakes_each_moving_axis_and_starts_none(shape: str) -> None:
    clock = Clock()
    accels = (ACCEL, 2 * ACCEL, ACCEL)
    drive = DriveMotion(shape=shape, sequence="xzy", start_delay_s=(0.0, 0.0, 0.01),
                        accel_mm_s2=accels)
    machine = machine_with(drive, clock)
    start = machine.actual()
    target = start + DELTA
    machine.move_to(target)
    clock.t = 0.25  # x is on its way (40 mm take ~0.5 s); z and y wait for it
    here = machine.actual()
    clock.t += DT
    v_x = (machine.actual()[0] - here[0]) / DT
    assert 0 < v_x <= SPEED * (1 + 1e-9) and here[1] == start[1] and here[2] == start[2]
    machine.stop()
    trail = []
    for _ in range(400):
        clock.t += DT
        trail.append(machine.actual())
    rest = trail[-1]
    assert not machine.status().moving
    assert not machine.status().in_position  # stopped short of the target
    steps = np.diff(np.vstack([here, *trail]), axis=0)
    assert np.all(steps[:, 0] >= -1e-12)  # x slows down forward, never back
    assert start[0] < rest[0] < target[0]  # and stops before its target
    # a constant-deceleration brake at x's acceleration: v²/2a beyond where it was
    assert rest[0] - here[0] - v_x * DT == pytest.approx(v_x**2 / (2 * accels[0]), rel=0.05)
    np.testing.assert_array_equal(rest[1:], start[1:])  # z and y never started
    clock.t += 10.0
    np.testing.assert_array_equal(machine.actual(), rest)


def test_stop_never_passes_the_target_at_any_instant() -> None:
    # Stops late in a move (the axes decelerating, some arrived): every rest lies
    # between start and target on every axis, for every shape and sequence.
    for shape in ("trapezoid", "scurve", "cosine"):
        for sequence in (None, "yzx"):
            for fraction in (0.3, 0.7, 0.95, 0.999):
                clock = Clock()
                machine = machine_with(DriveMotion(shape=shape, sequence=sequence), clock)
                start = machine.actual()
                target = start + DELTA
                clock.t = fraction * machine.move_to(target)
                machine.stop()
                clock.t += 10.0
                rest = machine.actual()
                lo, hi = np.minimum(start, target), np.maximum(start, target)
                assert np.all(rest >= lo - 1e-12) and np.all(rest <= hi + 1e-12), \
                    (shape, sequence, fraction, rest - target)


def trapezoid_position(d: float, v: float, a: float, t: np.ndarray) -> np.ndarray:
    """Closed-form rest-to-rest trapezoid (a triangle when too short to cruise)."""
    t_acc = v / a
    if d <= v * t_acc:
        t_acc, v = math.sqrt(d / a), math.sqrt(d * a)
    total = 2 * t_acc + (d - v * t_acc) / v
    t = np.clip(t, 0.0, total)
    up = 0.5 * a * t**2
    cruise = 0.5 * v * t_acc + v * (t - t_acc)
    down = d - 0.5 * a * (total - t) ** 2
    return np.where(t < t_acc, up, np.where(t <= total - t_acc, cruise, down))


def test_independent_is_unchanged() -> None:
    # The plain string and the default DriveMotion give exactly the same positions,
    # and those are each axis on its own trapezoid from the same instant: what the
    # closed form says.
    clocks = (Clock(), Clock())
    named = machine_with("independent", clocks[0])
    plain = machine_with(DriveMotion(), clocks[1])
    assert named.drive == plain.drive == DriveMotion.named("independent")
    assert named.motion == "independent"
    a = named.actual()
    b = a + np.array([60.0, -5.9, -0.4])
    duration = named.move_to(b)
    assert plain.move_to(b) == duration
    times = np.linspace(0.0, duration, 101)
    for t in times:
        clocks[0].t = clocks[1].t = t
        got = named.actual()
        np.testing.assert_array_equal(got, plain.actual())
        closed = [a[i] + math.copysign(1.0, b[i] - a[i])
                  * float(trapezoid_position(abs(b[i] - a[i]), SPEED, ACCEL, np.array(t)))
                  for i in range(3)]
        np.testing.assert_allclose(got, closed, atol=1e-9)


def test_coordinated_shapes_stay_on_the_straight_line() -> None:
    for shape in ("trapezoid", "scurve", "cosine"):
        clock = Clock()
        machine = machine_with(DriveMotion(coordinated=True, shape=shape), clock)
        a = machine.actual()
        duration = machine.move_to(a + DELTA)
        for k in range(1, 10):
            clock.t = duration * k / 10
            u = (machine.actual() - a) / DELTA
            assert np.ptp(u) < 1e-12 and 0 < u[0] < 1
        clock.t = duration * 0.4
        machine.stop()  # coordinated braking stays on the line too
        clock.t += 10.0
        u = (machine.actual() - a) / DELTA
        assert np.ptp(u) < 1e-12 and 0 < u[0] < 1
    with pytest.raises(ValueError, match="coordinated"):
        DriveMotion(coordinated=True, sequence="xyz")
    with pytest.raises(ValueError, match="coordinated"):
        DriveMotion(coordinated=True, shape=("scurve", "cosine", "scurve"))


def test_drive_motion_refuses_what_no_drive_does() -> None:
    for bad in ({"shape": "square"}, {"shape": ("scurve", "cosine")},
                {"accel_mm_s2": 0.0}, {"accel_mm_s2": (1.0, -2.0, 3.0)},
                {"start_delay_s": (0.0, -0.001, 0.0)}, {"sequence": "xxz"},
                {"sequence": "xy"}, {"jerk_time_s": 0.0}):
        with pytest.raises(ValueError):
            DriveMotion(**bad)
    d = DriveMotion(shape="cosine", accel_mm_s2=700)
    assert d.shapes == ("cosine",) * 3 and d.accels(5.0) == (700.0,) * 3


# --- out of stroke, counted from the trajectory -------------------------------------------

@pytest.fixture
def short_station() -> Iterator[tuple[VirtualStation, Clock]]:
    """Two 7 mm gauges preloaded 3.5 mm on leg x, an independent drive, a stepped
    clock, no noise. With each axis on its own trapezoid, Π0 → Π_x^+ swings them
    by −3.0 mm (within), Π_x^− → Π0 by +2.5 mm (within), a single Π_x^+ → Π_x^−
    by −8.8 mm (a figure from a held-out controller): 5.3 mm past the end."""
    clock = Clock()
    gauges = GaugeSpec(noise_mm=0.0, line_time=False, strokes={"A": (7.0, 3.5), "B": (7.0, 3.5)})
    with VirtualStation(drive=INDEPENDENT, gauges=gauges, clock=clock) as st:
        st.mount("A", "x", "y")
        st.mount("B", "x", "z")
        yield st, clock


PLUS, MINUS = (orthocal.posture(s, "x", GEOMETRY) for s in "+-")


def travel_by_reading(st: VirtualStation, clock: Clock, name: str, target: np.ndarray,
                      dt: float = DT) -> tuple[float, float]:
    """(min, max) plunger travel of gauge ``name`` through a move, stepped through
    its own source as a reading sees it (before the clamp)."""
    gauge = st.indicators[name]
    duration = st.machine.move_to(target)
    end = clock.t + duration
    seen = []
    while clock.t <= end + dt:
        seen.append(gauge.travel_mm(gauge._source()))  # type: ignore[misc]
        clock.t += dt
    return min(seen), max(seen)


def test_a_move_past_the_stroke_is_counted_without_any_reading(
        short_station: tuple[VirtualStation, Clock]) -> None:
    st, clock = short_station
    clock.t += st.machine.move_to(PLUS) + 0.01
    assert st.out_of_stroke_count == 0  # a move within the stroke counts nothing
    clock.t += st.machine.move_to(MINUS) + 0.01  # one COMMAND 1: the 8.8 mm swing
    events = st.out_of_stroke
    assert {e.gauge for e in events} == {"A", "B"}
    assert all(e.move == 2 and e.kind == "move" and e.end == "low" for e in events)
    # nobody read a gauge: the readings' own count saw nothing
    assert all(g.requests == 0 and g.clamped == 0 for g in st.indicators.values())
    # how far past the end: what stepping through the same move reading A says
    for target in (PI0, PLUS):
        clock.t += st.machine.move_to(target) + 0.01
    assert st.out_of_stroke_count == 2
    lo, _ = travel_by_reading(st, clock, "A", MINUS)
    a_events = [e for e in st.out_of_stroke if e.gauge == "A"]
    assert [e.move for e in a_events] == [2, 5]
    assert a_events[-1].past_mm == pytest.approx(-3.5 - lo, abs=0.002)
    assert a_events[0].past_mm == pytest.approx(a_events[-1].past_mm, abs=1e-6)
    assert a_events[0].past_mm == pytest.approx(8.8 - 3.5, abs=0.01)


def test_ten_microns_past_the_end_are_not_missed(
        short_station: tuple[VirtualStation, Clock]) -> None:
    st, clock = short_station
    lo, hi = travel_by_reading(st, clock, "A", PLUS)
    clock.t += st.machine.move_to(PI0) + 0.01
    assert lo == pytest.approx(-3.0, abs=0.01) and hi < 0.01
    assert st.out_of_stroke_count == 0
    # a gauge preloaded so that this very move takes it 10 µm past its end
    gauge = st.indicators["A"]
    gauge.stroke_mm, gauge.preload_mm = 2 * (-lo - 0.010), -lo - 0.010
    st.mount("A", "x", "y")  # remounted at Π0 with that preload
    clock.t += st.machine.move_to(PLUS) + 0.01
    (event,) = st.out_of_stroke
    assert (event.gauge, event.end, event.move) == ("A", "low", 3)
    assert event.past_mm == pytest.approx(0.010, abs=0.001)


def test_the_brake_after_a_stop_and_a_homing_are_segments_too(
        short_station: tuple[VirtualStation, Clock]) -> None:
    # Π0 → Π_x^− stopped at 0.1 s: the move so far swung the gauges by −2.4 mm
    # (within), the braking takes them to −4.5 mm (past), and the homing back to
    # Π0 starts there.
    st, clock = short_station
    m = st.machine
    m.move_to(MINUS)
    clock.t += 0.1
    m.stop()
    clock.t += 1.0
    events = st.out_of_stroke
    assert {(e.kind, e.move) for e in events} == {("brake", 1)}
    assert {e.gauge for e in events} == {"A", "B"}
    past = events[0].past_mm
    assert past == pytest.approx(1.04, abs=0.01)
    clock.t += m.home() + 0.01
    assert m.status().homed
    homing = st.out_of_stroke[2:]
    assert {(e.kind, e.move) for e in homing} == {("home", None)}
    assert homing[0].past_mm == pytest.approx(past, abs=1e-6)


def test_only_mounted_gauges_count_with_their_mounting_in_force(
        short_station: tuple[VirtualStation, Clock]) -> None:
    st, clock = short_station
    st.unmount("A")
    duration = st.machine.move_to(MINUS)  # −6.7 mm at 0.25 s
    clock.t += 0.1
    st.unmount("B")  # off before its plunger left the stroke: nothing to count
    clock.t += duration
    assert st.out_of_stroke_count == 0
    # mounted at Π_x^− (zeroed there); the way back is within, then out again
    st.mount("A", "x", "y")
    st.mount("B", "x", "z")
    clock.t += st.machine.move_to(PI0) + 0.01
    assert st.out_of_stroke_count == 0
    duration = st.machine.move_to(MINUS)
    clock.t += duration / 2  # past the worst of the swing
    st.unmount("B")  # what B went through so far counts
    clock.t += duration
    events = st.out_of_stroke
    assert sorted((e.gauge, e.move) for e in events) == [("A", 3), ("B", 3)]
    assert all(e.past_mm == pytest.approx(6.75 - 3.5, abs=0.01) for e in events)


def test_a_knocked_stand_is_seen_by_the_readings_and_the_count() -> None:
    clock = Clock()
    with VirtualStation(drive=INDEPENDENT, gauges=GaugeSpec(noise_mm=0.0, line_time=False),
                        clock=clock) as st:
        st.mount("A", "x", "y")
        st.mount("B", "x", "z")
        a, unknocked = st.indicators["A"], st.source("x", "y")
        # a 12.5 mm gauge, 6.25 mm from its stop: knocked 9 mm in half-way to Π_x^+
        st.knock("A", 9.0, on_move=1, at_fraction=0.5)
        with pytest.raises(ValueError):
            st.knock("A", 1.0, on_move=0, at_fraction=0.5)  # that move is long gone
        duration = st.machine.move_to(PLUS)
        clock.t += 0.45 * duration
        assert a._value_mm() == pytest.approx(a.travel_mm(unknocked()), abs=0.001)
        clock.t += 0.1 * duration
        after = a.travel_mm(unknocked()) + 9.0
        assert a._value_mm() == pytest.approx(min(after, 6.25), abs=0.001)
        clock.t += duration
        assert a._value_mm() == pytest.approx(6.25)  # at its stop
        (event,) = st.out_of_stroke
        assert (event.gauge, event.move, event.end) == ("A", 1, "high")
        assert event.past_mm == pytest.approx(9.0 - 6.25, abs=0.001)  # at Π_x^+: 0 + 9
        # remounted, the knock is gone; a 1 mm knock at the end of the way back shows
        st.mount("A", "x", "y")
        assert a._value_mm() == 0.0
        st.knock("A", 1.0, on_move=2, at_fraction=1.0)
        clock.t += st.machine.move_to(PI0) + 0.01
        assert st.out_of_stroke_count == 1
        assert a._value_mm() == pytest.approx(a.travel_mm(unknocked()) + 1.0, abs=0.001)


# --- what the station is told ---------------------------------------------------------------

def test_config_tells_the_station_nothing_of_the_drives_timing() -> None:
    drives: list[tuple[Any, dict[str, Any]]] = [
        ("independent", {}),
        (DriveMotion(shape="scurve", sequence="zyx"), {"actual_accel_mm_s2": 5000.0}),
        ("coordinated", {}),
        (DriveMotion(coordinated=True, shape="cosine"), {}),
    ]
    for drive, extra in drives:
        with SimulatedStation(drive=DriveSpec(motion=drive, **extra)) as st:
            controller = st.config()["controller"]
            coordinated = st.machine.drive.coordinated
            assert ("motion" in controller) == coordinated
            if coordinated:
                assert controller["motion"] == "coordinated"
            assert controller["accel_mm_s2"] == st.accel_mm_s2
            assert not any(k.startswith("drive") for k in controller)
            parse_config(st.config(), "test")  # what it hands out loads
            if extra:  # the drive accelerates as it likes, the config says otherwise
                assert st.machine.accel_mm_s2 == 5000.0 != controller["accel_mm_s2"]


def test_the_drives_own_acceleration_is_the_one_it_moves_with() -> None:
    clock = Clock()
    drive = DriveSpec(motion="independent", speed_mm_s=SPEED, accel_mm_s2=ACCEL,
                      actual_accel_mm_s2=ACCEL / 4)
    with SimulatedStation(drive=drive, clock=clock) as st:
        d = 2.0  # a triangle at either acceleration
        duration = st.machine.move_to(st.machine.actual() + np.array([d, 0.0, 0.0]))
        assert duration == pytest.approx(2 * math.sqrt(d / (ACCEL / 4)))
        assert st.config()["controller"]["accel_mm_s2"] == ACCEL
