"""Indicator I/O benchmark (a script, not a test): how close the driver gets to
the serial line's own limit, and whether reading six gauges costs one.

    /work/venv/bin/python bench/gauge_io.py [--reads 200] [--group-reads 50] [--repeats 3]

Line time is emulated by the simulator (ptys ignore baud), so the limit is
``baud / (bits per char * (request + reply chars))`` readings per second;
targets: >= 0.9 of it, and six-at-once / one <= 1.2.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import serial

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.indicator_protocols import IndicatorProtocol, make_protocol
from drivers.indicators import IndicatorGroup, SerialIndicator
from drivers.sim.pty_gauges import SimIndicator


def line_limit(protocol: IndicatorProtocol, baud: int, reply_chars: int) -> float:
    """Readings per second the line allows, with no gap between characters."""
    chars = len(protocol.request) + reply_chars
    return baud / (protocol.bits_per_char * chars)


def reply_chars(protocol: IndicatorProtocol, value_mm: float) -> int:
    assert protocol.reply_format is not None
    text = protocol.reply_format.format(value=value_mm / protocol.mm_per_unit)
    return len(text) + len(protocol.terminator)


def rate(name: str, baud: int | None, reads: int) -> float:
    """Readings per second of one driver against one simulated gauge."""
    with SimIndicator(name, lambda: 0.123, zero_mm=0.0, baud=baud) as sim:
        with SerialIndicator("A", sim.port, name) as ind:
            ind.read_n(5)  # warm-up: first-time costs are not the steady state
            t0 = time.perf_counter()
            ind.read_n(reads)
            return reads / (time.perf_counter() - t0)


def rate_read_until(name: str, reads: int) -> float:
    """The same exchange with pyserial's read_until, for comparison (no line time)."""
    proto = make_protocol(name)
    with SimIndicator(proto, lambda: 0.123, zero_mm=0.0) as sim:
        with serial.serial_for_url(sim.port, timeout=1.0, **proto.serial_settings()) as port:
            t0 = time.perf_counter()
            for _ in range(reads):
                port.reset_input_buffer()
                port.write(proto.request)
                if not port.read_until(proto.terminator).endswith(proto.terminator):
                    raise RuntimeError("read_until timed out")
            return reads / (time.perf_counter() - t0)


def group_ratio(baud: int, n: int, repeats: int) -> tuple[float, float, float]:
    """(time to read six at once, time to read one, ratio), medians over repeats."""
    names = "ABCDEF"
    sims = [
        SimIndicator("mitutoyo", lambda i=i: 0.1 * i, zero_mm=0.0, baud=baud, name=x)
        for i, x in enumerate(names)
    ]
    try:
        for sim in sims:
            sim.start()
        with IndicatorGroup(
            [SerialIndicator(x, sims[i].port, "mitutoyo") for i, x in enumerate(names)]
        ) as group:
            group.read(2)  # warm-up: starts the six workers
            one, six = [], []
            for _ in range(repeats):
                t0 = time.perf_counter()
                group.read(n, names=["A"])
                one.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                group.read(n)
                six.append(time.perf_counter() - t0)
    finally:
        for sim in sims:
            sim.close()
    t_one, t_six = statistics.median(one), statistics.median(six)
    return t_six, t_one, t_six / t_one


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reads", type=int, default=200, help="readings per rate measurement")
    ap.add_argument("--group-reads", type=int, default=50, help="readings per gauge, group test")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)

    print("Indicator readings per second, line time emulated by the simulator")
    print(
        f"{'protocol':10} {'baud':>5} {'bits':>4} {'chars':>5} {'limit/s':>8} "
        f"{'got/s':>8} {'fraction':>8}"
    )
    headline = 0.0
    for name, baud in (("mitutoyo", 9600), ("sylvac", 9600), ("mahr", 9600), ("sylvac", 4800)):
        proto = make_protocol(name)
        chars = len(proto.request) + reply_chars(proto, 0.123)
        limit = line_limit(proto, baud, reply_chars(proto, 0.123))
        got = rate(name, baud, args.reads)
        if (name, baud) == ("mitutoyo", 9600):
            headline = got / limit
        print(
            f"{name:10} {baud:5d} {proto.bits_per_char:4g} {chars:5d} {limit:8.1f} "
            f"{got:8.1f} {got / limit:8.3f}"
        )

    print("\nWithout line time (driver + pty overhead only), mitutoyo:")
    fast = rate("mitutoyo", None, args.reads * 5)
    slow = rate_read_until("mitutoyo", args.reads * 5)
    print(f"  driver (buffered chunks) {fast:8.0f}/s   pyserial read_until {slow:8.0f}/s")

    t_six, t_one, ratio = group_ratio(9600, args.group_reads, args.repeats)
    print(f"\nSix gauges at once vs one (mitutoyo, 9600 baud, {args.group_reads} readings each):")
    print(f"  one {t_one:.3f} s   six {t_six:.3f} s   ratio {ratio:.3f}")

    ok = headline >= 0.9 and ratio <= 1.2
    print(
        f"\nline-rate fraction {headline:.3f} (target >= 0.9), "
        f"six/one {ratio:.3f} (target <= 1.2): {'OK' if ok else 'BELOW TARGET'}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
