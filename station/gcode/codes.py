"""The G and M codes compensate knows: their modal groups as RS274/NGC (LinuxCNC's
G-code reference, "Modal Groups") defines them, and the ones it refuses, each with
why. Codes are the number times ten (G38.2 is 382, G59.3 is 593).

A code is refused when the controller would move the tool along a path compensate
cannot see in the program, or would shift the program's points by an amount it does
not know: written through uncompensated, such a word would put the tool somewhere
nobody checked.
"""

from __future__ import annotations

# G codes by modal group ("non-modal" is group 0).
G_GROUPS: dict[str, tuple[int, ...]] = {
    "non-modal": (40, 100, 280, 281, 300, 301, 520, 530, 920, 921, 922, 923),
    "motion": (0, 10, 20, 30, 50, 51, 52, 53, 330, 331, 382, 383, 384, 385, 730, 760, 800,
               810, 820, 830, 840, 850, 860, 870, 880, 890),
    "plane": (170, 180, 190, 171, 181, 191),
    "distance": (900, 910),
    "arc distance": (901, 911),
    "feed rate mode": (930, 940, 950),
    "units": (200, 210),
    "cutter compensation": (400, 410, 420, 411, 421),
    "tool length offset": (430, 431, 432, 490),
    "canned cycle return": (980, 990),
    "coordinate system": (540, 550, 560, 570, 580, 590, 591, 592, 593),
    "path control": (610, 611, 640),
    "spindle speed mode": (960, 970),
    "lathe diameter mode": (70, 80),
}
G_GROUP = {code: group for group, codes in G_GROUPS.items() for code in codes}

# M codes by modal group; M7 and M8 may stand together (both coolants on).
M_GROUPS: dict[str, tuple[int, ...]] = {
    "stopping": (0, 10, 20, 300, 600),
    "tool change": (60, 610),
    "spindle": (30, 40, 50),
    "coolant": (70, 80, 90),
    "override switches": (480, 490, 500, 510, 520, 530),
    "user defined": tuple(range(1000, 2000, 10)),
}
M_GROUP = {code: group for group, codes in M_GROUPS.items() for code in codes}
#: The stopping M codes act after the block's motion (RS274/NGC's order of execution):
#: a motion written as several lines carries them on its last line.
STOPS = frozenset(M_GROUPS["stopping"])

_SPLINE = "splines are not compensated (only lines and arcs are linearised)"
_CANNED = ("canned cycles are not compensated: their moves are made by the controller, "
           "not written in the program; expand the cycle into G0/G1 moves")
_OFFSET = ("shifts the program's coordinates by an amount compensate does not see: the "
           "compensated points would be off by it; give the work origin as --work-offset")
_STORED = "moves to a position stored in the controller, which compensate does not know"

REFUSED_G: dict[int, str] = {
    50: _SPLINE, 51: _SPLINE, 52: _SPLINE, 53: _SPLINE,
    330: "spindle-synchronised motion is not compensated",
    331: "rigid tapping is not compensated",
    **{c: "probing is not compensated: the move ends where the probe trips, which no "
          "program can say" for c in (382, 383, 384, 385)},
    **{c: _CANNED for c in (730, 760, 810, 820, 830, 840, 850, 860, 870, 880, 890)},
    **{c: "cutter radius compensation offsets the path in the controller, after "
          "compensate: the controller's path would no longer be the one compensated; "
          "compensate the tool's centre path instead" for c in (410, 420, 411, 421)},
    **{c: "a tool length offset shifts the tool point in the controller by an amount "
          "compensate does not know; program the tool point" for c in (430, 431, 432)},
    520: _OFFSET, 920: _OFFSET, 921: _OFFSET, 922: _OFFSET, 923: _OFFSET,
    280: _STORED, 281: _STORED, 300: _STORED, 301: _STORED,
    530: "machine coordinates bypass the work offset compensate assumed",
    100: "sets offsets or tool data in the controller, which would shift the program's "
         "points by amounts compensate does not see",
    930: "inverse time feed: each segment of a subdivided motion would need its own F; "
         "use G94",
    **{c: "selects another work coordinate system: --work-offset gives one origin, the "
          "program's" for c in (550, 560, 570, 580, 590, 591, 592, 593)},
    **{c: "the U, V, W planes: axes compensate does not know" for c in (171, 181, 191)},
    70: "lathe diameter mode: X would mean twice the tool's distance",
}

REFUSED_M: dict[int, str] = {
    980: "subroutine calls are not compensated; expand them into the program",
    990: "subroutine returns are not compensated; expand them into the program",
    720: "restores a saved modal state (units, distance mode, plane) that compensate "
         "does not follow",
    730: "saves and restores the modal state at a subroutine's end, which compensate "
         "does not follow",
}

#: Axes of machines with more than three: compensate knows X, Y, Z only.
OTHER_AXES = frozenset("ABCUVW")


def named(letter: str, code: int) -> str:
    """``G38.2`` for ("G", 382)."""
    whole, tenth = divmod(code, 10)
    return f"{letter}{whole}" + (f".{tenth}" if tenth else "")
