"""The deviation keys of the record ("+xy", "+30xy", "+@0.75xy") and their order: a
leg, its gauge plane, its posture, its direction. result.json keeps its deviations in
this order; the report reads them so."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable


def dev_parts(key: str) -> tuple[str, str, str] | None:
    """(posture, leg, direction) of "+xy", of a stroke key such as "+30xy", or of one
    read in a second gauge plane, "+@0.75xy"."""
    if re.fullmatch(r"[+-](\d+(\.\d*)?|\.\d+)?(@0?\.\d+)?[xyz][xyz]", key):
        return key[:-2], key[-2], key[-1]
    return None


def dev_keys(*tables: Iterable[str]) -> list[str]:
    """The deviation keys of ``tables`` (maps keyed by them), in :func:`dev_order`."""
    present: set[str] = set()
    for t in tables:
        present.update(t)
    return sorted(present, key=dev_order)


def dev_order(key: str) -> tuple[object, ...]:
    """Leg, then its gauge plane (the middle first), then posture from ρmax down to
    ρmin ('+', '+30', '-50', '-'), then direction: DEVIATION_KEYS' order, with
    intermediate strokes and second planes in their place."""
    parts = dev_parts(key)
    if parts is None:
        return (1, key)
    posture, leg, d = parts
    posture, _, plane = posture.partition("@")
    s = {"+": math.inf, "-": -math.inf}.get(posture)
    return (0, leg, float(plane) if plane else 0.5, -(float(posture) if s is None else s), d)
