"""The indicator driver against simulated gauges, real bytes through pseudo-terminals."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import serial

from drivers.device_errors import IndicatorPortError, IndicatorReplyError, IndicatorTimeout
from drivers.indicator_protocols import BUILTIN_PROTOCOLS, make_protocol
from drivers.indicators import IndicatorGroup, SerialIndicator
from drivers.sim.faults import IndicatorFaults
from drivers.sim.pty_gauges import SimIndicator

PROTOCOLS = sorted(BUILTIN_PROTOCOLS)


class Leg:
    """A plain stand-in for the virtual machine's leg coordinate (mm)."""

    def __init__(self, mm: float = 0.0) -> None:
        self.mm = mm

    def __call__(self) -> float:
        return self.mm


@contextmanager
def rig(
    protocol: Any,
    source: Callable[[], float],
    *,
    timeout_s: float = 1.0,
    retries: int = 3,
    reopen_s: float = 0.3,
    **sim_kw: Any,
) -> Iterator[tuple[SimIndicator, SerialIndicator, list[dict[str, Any]]]]:
    events: list[dict[str, Any]] = []
    with SimIndicator(protocol, source, **sim_kw) as sim:
        with SerialIndicator(
            "A", sim.port, protocol, timeout_s=timeout_s, retries=retries, on_event=events.append,
            reopen_s=reopen_s,
        ) as ind:
            yield sim, ind, events


def on_grid(value: float, step: float = 0.001) -> bool:
    return abs(value / step - round(value / step)) < 1e-6


@pytest.mark.parametrize("name", PROTOCOLS)
def test_readings_follow_the_source_at_the_protocols_own_line_rate(name: str) -> None:
    leg = Leg(10.0)
    baud = BUILTIN_PROTOCOLS[name].baudrate
    with rig(name, leg, baud=baud) as (sim, ind, events):
        for mm in (10.0, 10.1234, 9.87651, -2.5, 10.0004):
            leg.mm = mm
            value = ind.read()
            assert abs(value - (mm - 10.0)) <= 0.0005 + 1e-9
            assert on_grid(value)
        assert sim.requests == sim.replies == 5
    assert events == []


@pytest.mark.parametrize("name", PROTOCOLS)
def test_read_n_with_noise_is_quantised_and_centred(name: str) -> None:
    leg = Leg(3.0)
    with rig(name, leg, zero_mm=0.0, noise_mm=0.004, seed=11) as (_, ind, _events):
        values = ind.read_n(40)
    assert len(values) == 40
    assert all(on_grid(v) for v in values)
    assert len(set(values)) > 3  # the noise shows
    mean = sum(values) / len(values)
    assert abs(mean - 3.0) < 0.004  # 6 sigma of the mean of 40


def test_same_seed_same_readings() -> None:
    def run(seed: int) -> list[float]:
        with rig("mitutoyo", Leg(1.0), zero_mm=0.0, noise_mm=0.01, seed=seed) as (_, ind, _e):
            return ind.read_n(10)

    assert run(5) == run(5)
    assert run(5) != run(6)


def test_readings_taken_while_the_axes_move_leave_those_at_rest_unchanged() -> None:
    # The plunger guard reads as often as its polls fit into a move: those readings
    # draw their noise apart, so that a seeded run's readings at its stops repeat.
    def at_rest_readings(polls: int) -> list[float]:
        moving = [False]
        with rig("mitutoyo", Leg(1.0), zero_mm=0.0, noise_mm=0.01, seed=5) as (sim, ind, _e):
            sim.at_rest = lambda: not moving[0]
            first = ind.read_n(3)
            moving[0] = True
            ind.read_n(polls)
            moving[0] = False
            return first + ind.read_n(3)

    assert at_rest_readings(0) == at_rest_readings(4) == at_rest_readings(9)


def test_coarser_resolution_reversed_gauge_and_zero_button() -> None:
    leg = Leg(5.0)
    with rig("mitutoyo", leg, resolution_mm=0.01, sign=-1) as (sim, ind, _):
        leg.mm = 5.123
        assert ind.read() == pytest.approx(-0.12, abs=1e-9)
        sim.zero()
        assert ind.read() == 0.0
        leg.mm = 5.0
        assert ind.read() == pytest.approx(0.12, abs=1e-9)


def test_mount_moves_the_gauge_to_another_leg_and_unmount_frees_it() -> None:
    leg_x, leg_y = Leg(1.0), Leg(-7.0)
    with rig("sylvac", leg_x, unmounted_mm=-6.0) as (sim, ind, _):
        leg_x.mm = 1.5
        assert ind.read() == pytest.approx(0.5, abs=1e-9)
        sim.unmount()
        assert not sim.mounted
        leg_x.mm = 4.0
        assert ind.read() == -6.0  # lying on the bench, whatever the legs do
        sim.mount(leg_y)  # zeroed where it was put
        assert sim.mounted
        assert ind.read() == 0.0
        leg_y.mm = -7.25
        leg_x.mm = 100.0
        assert ind.read() == pytest.approx(-0.25, abs=1e-9)
        sim.mount(leg_x, zero_mm=99.0)
        assert ind.read() == pytest.approx(1.0, abs=1e-9)


def test_generic_protocol_through_the_simulator() -> None:
    proto = make_protocol(
        "generic",
        {
            "request": "\x05",
            "terminator": "\r\n",
            "reply_pattern": r"X=([+-]\d+)",
            "reply_format": "X={value:+.0f}",
            "unit": "um",
        },
    )
    leg = Leg(0.0)
    with rig(proto, leg, zero_mm=0.0, baud=19200) as (_, ind, _e):
        leg.mm = 0.4567
        assert ind.read() == pytest.approx(0.457, abs=1e-9)


def test_simulator_answers_only_its_request_and_keeps_cr_lf() -> None:
    with SimIndicator("mahr", Leg(2.0), zero_mm=0.0) as sim:
        with serial.serial_for_url(sim.port, timeout=1.0) as port:
            port.write(b"junk")
            port.write(b"?")
            port.write(b"\r")  # a request split across writes still counts once
            assert port.read_until(b"\n") == b"2.0000 mm\r\n"
            port.write(b"1\r")  # mitutoyo's request means nothing to a Mahr gauge
            port.write(b"?\r")
            assert port.read_until(b"\n") == b"2.0000 mm\r\n"
        assert sim.requests == 2


def test_a_failing_source_costs_one_reply_not_the_gauge() -> None:
    calls = {"n": 0}

    def flaky() -> float:
        calls["n"] += 1
        if calls["n"] == 1:
            raise RuntimeError("virtual machine not ready")
        return 0.75

    with rig("sylvac", flaky, zero_mm=0.0, timeout_s=0.1) as (sim, ind, ev):
        assert ind.read() == 0.75
        assert len(ev) == 1 and "no reply" in ev[0]["error"]
        assert isinstance(sim.source_error, RuntimeError)


# --- fault knobs ------------------------------------------------------------------


def test_dropped_reply_is_retried() -> None:
    faults = IndicatorFaults(drop_next=2)
    with rig("mitutoyo", Leg(1.0), zero_mm=0.0, faults=faults, timeout_s=0.1) as (sim, ind, ev):
        assert ind.read() == 1.0
        assert [e["attempt"] for e in ev] == [1, 2]
        assert all("no reply" in e["error"] for e in ev)
        assert faults.drop_next == 0
        assert sim.requests == 3


def test_always_dropped_is_a_timeout_naming_the_port() -> None:
    faults = IndicatorFaults(drop_rate=1.0)
    with rig("sylvac", Leg(), faults=faults, timeout_s=0.05, retries=2, seed=1) as (sim, ind, ev):
        with pytest.raises(IndicatorTimeout) as info:
            ind.read()
        assert sim.port in str(info.value) and "indicator A" in str(info.value)
        assert len(ev) == 2
        assert sim.replies == 0


@pytest.mark.parametrize("name", PROTOCOLS)
@pytest.mark.parametrize(("mode", "words"), [("corrupt", "garbled"), ("truncate", "partial")])
def test_garbled_reply_is_retried(name: str, mode: str, words: str) -> None:
    faults = IndicatorFaults(garble_next=1, garble_mode=mode)  # type: ignore[arg-type]
    leg = Leg(0.25)
    with rig(name, leg, zero_mm=0.0, faults=faults, timeout_s=0.1, seed=3) as (_, ind, ev):
        assert ind.read() == 0.25
        assert len(ev) == 1 and words in ev[0]["error"]
        assert ind.read() == 0.25
        assert len(ev) == 1


def test_always_garbled_is_a_reply_error() -> None:
    faults = IndicatorFaults(garble_rate=1.0, garble_mode="corrupt")
    with rig("mahr", Leg(), faults=faults, seed=4) as (_, ind, ev):
        with pytest.raises(IndicatorReplyError, match="garbled"):
            ind.read()
        assert len(ev) == 3


def test_random_faults_at_a_rate_are_absorbed_by_retries() -> None:
    faults = IndicatorFaults(garble_rate=0.3, drop_rate=0.2, late_rate=0.2, late_s=0.01)
    leg = Leg(0.5)
    with rig("mitutoyo", leg, zero_mm=0.0, faults=faults, seed=2024, timeout_s=0.1, retries=10) as (
        _,
        ind,
        ev,
    ):
        assert ind.read_n(15) == [0.5] * 15
    assert ev  # some faults happened and were reported


@pytest.mark.parametrize(("name", "reply"), [("mitutoyo", "91"), ("sylvac", "ERR1")])
def test_gauge_error_reply_is_retried(name: str, reply: str) -> None:
    faults = IndicatorFaults(error_next=1)
    with rig(name, Leg(2.0), zero_mm=0.0, faults=faults) as (_, ind, ev):
        assert ind.read() == 2.0
        assert len(ev) == 1 and "gauge error 1" in ev[0]["error"] and reply in ev[0]["error"]


@pytest.mark.parametrize("name", ["mitutoyo", "sylvac"])
def test_persistent_gauge_error_is_a_reply_error_with_its_code(name: str) -> None:
    faults = IndicatorFaults(error_rate=1.0, error_code=5)
    with rig(name, Leg(), faults=faults, retries=1) as (sim, ind, _):
        with pytest.raises(IndicatorReplyError, match="gauge error 5") as info:
            ind.read()
        assert sim.port in str(info.value)


def test_gauge_without_error_grammar_stays_silent_on_error() -> None:
    faults = IndicatorFaults(error_rate=1.0)
    with rig("mahr", Leg(), faults=faults, timeout_s=0.05, retries=1) as (_, ind, _e):
        with pytest.raises(IndicatorTimeout, match="no reply"):
            ind.read()


def test_late_reply_within_the_timeout_is_just_late() -> None:
    faults = IndicatorFaults(late_next=1, late_s=0.05)
    with rig("sylvac", Leg(1.0), zero_mm=0.0, faults=faults, timeout_s=1.0) as (_, ind, ev):
        assert ind.read() == 1.0
    assert ev == []


def test_reply_later_than_the_timeout_is_retried_and_later_reads_recover() -> None:
    faults = IndicatorFaults(late_next=1, late_s=0.25)
    with rig("mitutoyo", Leg(1.0), zero_mm=0.0, faults=faults, timeout_s=0.1, retries=5) as (
        _,
        ind,
        ev,
    ):
        assert ind.read() == 1.0
        assert ev and "no reply" in ev[0]["error"]
        # The late reply and the answers to the retries may still be on the line;
        # they are flushed or rejected, never mistaken for a different reading.
        assert ind.read_n(5) == [1.0] * 5


def test_close_interrupts_a_pending_late_reply() -> None:
    faults = IndicatorFaults(late_rate=1.0, late_s=60.0)
    sim = SimIndicator("mitutoyo", Leg(), faults=faults).start()
    with SerialIndicator("A", sim.port, "mitutoyo", timeout_s=0.05, retries=0) as ind:
        with pytest.raises(IndicatorTimeout):
            ind.read()
    sim.close(timeout_s=5.0)  # raises if the thread were still waiting out the 60 s


def test_unplug_is_a_port_error_naming_the_port(tmp_path) -> None:
    # Behind a stable link, as a real adapter is: a bare /dev/pts path freed by the
    # unplug may be given to another process's pty, which the reopen would open.
    with rig("mitutoyo", Leg(1.0), zero_mm=0.0, link=tmp_path / "usb-A") as (sim, ind, ev):
        assert ind.read() == 1.0
        port = sim.port
        sim.unplug()
        assert not os.path.exists(port)
        with pytest.raises(IndicatorPortError) as info:
            ind.read()
        assert info.value.device == f"indicator A ({port})"
        assert "still gone after 0.3 s" in info.value.message
        # A dead port is not asked again, only reopened (within reopen_s).
        assert any(e["event"] == "reopen" for e in ev)
        # The driver tries to reopen it next time, and finds nothing there.
        with pytest.raises(IndicatorPortError, match="cannot open"):
            ind.read()


def test_adapter_pulled_and_plugged_back_behind_a_stable_link(tmp_path) -> None:
    link = tmp_path / "usb-Mitutoyo_A-if00-port0"
    with rig("mitutoyo", Leg(1.0), zero_mm=0.0, link=link, reopen_s=5.0) as (sim, ind, ev):
        assert sim.port == str(link) and os.path.realpath(link) == sim.tty
        assert ind.read() == 1.0
        sim.unplug_for(0.4)
        assert not os.path.lexists(link)
        assert ind.read_n(3) == [1.0] * 3  # waits for the adapter, then reads on
        assert os.path.realpath(link) == sim.tty  # a new pty (the kernel may reuse a number)
        kinds = [e["event"] for e in ev]
        assert kinds.count("reopened") == 1 and kinds.index("reopen") < kinds.index("reopened")
        assert all(e["port"] == str(link) for e in ev)


def test_opening_waits_for_a_port_being_plugged_in(tmp_path) -> None:
    link = tmp_path / "usb-Sylvac_B"
    with SimIndicator("sylvac", Leg(2.0), zero_mm=0.0, link=link) as sim:
        sim.unplug_for(0.4)
        events: list[dict[str, Any]] = []
        with SerialIndicator("B", str(link), "sylvac", reopen_s=5.0,
                             on_event=events.append) as ind:
            assert ind.read() == 2.0
        assert events[-1]["event"] == "reopened" and events[0]["event"] == "reopen"


def test_unplug_flag_set_at_run_time(tmp_path) -> None:
    faults = IndicatorFaults()
    # Behind a stable link: the freed /dev/pts path may go to another process's pty.
    with rig("sylvac", Leg(), faults=faults, timeout_s=0.2, retries=1,
             link=tmp_path / "usb-A") as (sim, ind, _):
        ind.read()
        faults.unplugged = True
        with pytest.raises((IndicatorPortError, IndicatorTimeout)) as info:
            for _ in range(50):  # until the simulator has noticed the flag
                ind.read()
        assert sim.port in str(info.value)


def test_opening_a_missing_port_is_a_port_error() -> None:
    with pytest.raises(IndicatorPortError) as info:
        SerialIndicator("Z", "/dev/pts/does-not-exist", "mahr", reopen_s=0.0)
    assert "/dev/pts/does-not-exist" in str(info.value)


# --- several gauges at once -------------------------------------------------------


def test_group_reads_six_gauges_concurrently() -> None:
    n = 6
    # Each gauge's reading waits until all six have received a request: it can
    # only succeed if the six requests are in flight together. A sequential read
    # would break the barrier (after its timeout) and read the sentinel instead.
    barrier = threading.Barrier(n, timeout=3.0)

    def leg(i: int) -> Callable[[], float]:
        def position() -> float:
            try:
                barrier.wait()
            except threading.BrokenBarrierError:
                return -99.0
            return 1.0 + 0.111 * i

        return position

    names = "ABCDEF"
    sims = [SimIndicator("mitutoyo", leg(i), zero_mm=0.0, name=names[i]) for i in range(n)]
    try:
        for sim in sims:
            sim.start()
        inds = [
            SerialIndicator(names[i], sims[i].port, "mitutoyo", timeout_s=5.0) for i in range(n)
        ]
        with IndicatorGroup(inds) as group:
            result = group.read(3)
            assert list(result) == list(names)
            for i, x in enumerate(names):
                assert result[x] == [pytest.approx(1.0 + 0.111 * i, abs=1e-9)] * 3
            assert not barrier.broken
            assert [s.requests for s in sims] == [3] * n
    finally:
        for sim in sims:
            sim.close()


def test_group_subset_and_single_failure() -> None:
    legs = {x: Leg(float(i)) for i, x in enumerate("ABC")}
    faults = IndicatorFaults(drop_rate=1.0)
    sims = {
        x: SimIndicator("sylvac", legs[x], zero_mm=0.0, name=x, faults=faults if x == "B" else None)
        for x in "ABC"
    }
    try:
        for sim in sims.values():
            sim.start()
        inds = [
            SerialIndicator(x, sims[x].port, "sylvac", timeout_s=0.05, retries=1) for x in "ABC"
        ]
        with IndicatorGroup(inds) as group:
            assert group.read(2, names=["C", "A"]) == {"C": [2.0, 2.0], "A": [0.0, 0.0]}
            assert sims["B"].requests == 0
            with pytest.raises(IndicatorTimeout) as info:
                group.read(1)
            assert info.value.device == f"indicator B ({sims['B'].port})"
            assert sims["A"].replies == 3 and sims["C"].replies == 3
    finally:
        for sim in sims.values():
            sim.close()
