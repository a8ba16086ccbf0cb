"""Comparing what a run wrote with what it wrote before, on any machine (imported
by the tests, like ``builders`` and ``truth``).

Another CPU takes another SIMD path in numpy and another BLAS kernel, so the same
seeded run differs in the last bits of its floats, and a few figures amplify them:
between this project's CI machine and a 2-core x86 machine without AVX-512
(OpenBLAS on the Haswell and on the Nehalem kernels), up to relative 1.4e-7 on a
fitted tilt near zero and absolute 8e-9 on an interval's end that is the difference
of two nearly equal figures (mm, mrad or none). What the station shows a user is at
most six significant digits, and µm to a tenth (1e-4 mm). So floats are equal here
within

    |a − b| ≤ ABS + REL·max(|a|, |b|),  ABS = 1e-7, REL = 1e-6

(in the figure's own unit: 0.1 nm on a figure in mm), more than ten times the
largest difference seen between machines and a thousand times below the finest
figure printed. What is exact stays exact: strings, record types, booleans,
integer counts, the keys of every mapping and the length of every list.

Printed text (report.html, plan.txt) is compared token by token: words and whole
numbers (counts, indices) exactly, each decimal number within one unit of its last
printed digit (a value that sits on a rounding boundary prints either way on two
machines; among the thousands of a report's plots, one or two do).
"""

from __future__ import annotations

import math
import re
from typing import Any

ABS = 1e-7
REL = 1e-6

_NUMBER = re.compile(r"[-+−]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def close(a: float, b: float) -> bool:
    """The floats ``a`` and ``b`` are the same figure (module docstring)."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= ABS + REL * max(abs(a), abs(b))


def differences(now: Any, before: Any, path: str = "") -> list[str]:
    """Where ``now`` and ``before`` (JSON-like values) differ beyond the tolerance,
    each as ``path: now != before`` (empty: the same)."""
    here = path or "<root>"
    if isinstance(now, bool) or isinstance(before, bool):
        return [] if now is before else [f"{here}: {now!r} != {before!r}"]
    if isinstance(now, int) and isinstance(before, int):
        return [] if now == before else [f"{here}: {now!r} != {before!r}"]
    if isinstance(now, (int, float)) and isinstance(before, (int, float)):
        return [] if close(float(now), float(before)) else [f"{here}: {now!r} != {before!r}"]
    if isinstance(now, dict) and isinstance(before, dict):
        if set(now) != set(before):
            return [f"{here}: keys {sorted(set(now) ^ set(before))} in one only"]
        return [d for k in now for d in differences(now[k], before[k], f"{path}.{k}")]
    if isinstance(now, list) and isinstance(before, list):
        if len(now) != len(before):
            return [f"{here}: {len(now)} items != {len(before)}"]
        return [d for i, (x, y) in enumerate(zip(now, before, strict=True))
                for d in differences(x, y, f"{path}[{i}]")]
    return [] if now == before else [f"{here}: {now!r} != {before!r}"]


def assert_same(now: Any, before: Any, what: str = "") -> None:
    """:func:`differences` is empty; the message lists the first few."""
    diffs = differences(now, before)
    assert not diffs, f"{what}: " + "; ".join(diffs[:8]) + (
        f" (and {len(diffs) - 8} more)" if len(diffs) > 8 else "")


def _printed(token: str) -> tuple[float, float]:
    """A printed number's value and one unit of its last digit (0 for a whole
    number: exact)."""
    text = token.replace("−", "-")
    mantissa, _, exponent = text.lower().partition("e")
    if "." not in mantissa:
        return float(text), 0.0
    decimals = len(mantissa.partition(".")[2])
    return float(text), 10.0 ** (-decimals + (int(exponent) if exponent else 0))


def text_differences(now: str, before: str) -> list[str]:
    """Where two printed texts differ: words and whole numbers exactly, decimals
    within one unit of their last printed digit (module docstring)."""
    words_now, words_before = _NUMBER.split(now), _NUMBER.split(before)
    nums_now, nums_before = _NUMBER.findall(now), _NUMBER.findall(before)
    if words_now != words_before or len(nums_now) != len(nums_before):
        for i, (a, b) in enumerate(zip(words_now, words_before, strict=False)):
            if a != b:
                return [f"text differs near {i}: {a[:80]!r} != {b[:80]!r}"]
        return [f"{len(words_now)} pieces of text != {len(words_before)}"]
    out = []
    for a, b in zip(nums_now, nums_before, strict=True):
        (va, ua), (vb, ub) = _printed(a), _printed(b)
        # Printed figures differ by whole units of their last digit: half a unit more
        # absorbs the binary error of parsing them, and still refuses two units.
        if abs(va - vb) > 1.5 * max(ua, ub):
            out.append(f"{a} != {b}")
    return out


def assert_same_text(now: str, before: str, what: str = "") -> None:
    """:func:`text_differences` is empty."""
    diffs = text_differences(now, before)
    assert not diffs, f"{what}: " + "; ".join(diffs[:8])
