"""``[joints]``: what the shop knows of each joint's positioning error (docs/design.md,
"Joints"), and the reader of the ISO 230-2 test files it names.

A test file is CSV: a header naming the columns ``target_mm``, ``forward_um``,
``reverse_um`` and optionally ``u_um`` (in any order), then one row per target.
``target_mm`` is the joint coordinate ρ as the station commands it (absolute, Π0 at
ρ = L), the deviations are actual − target as ISO 230-2 defines them, ``forward``
approached in +ρ, ``u_um`` the test's expanded uncertainty (95 %). Blank lines and
lines starting with ``#`` are skipped. A bad row (a missing column, a value that is
not a finite number, targets not strictly increasing) is one line naming the file
and the line: :func:`parse_joint_test` is pure (the text in), :func:`read_joint_test`
reads the file. Whether a test spans the travel the run needs is the plan check's
(station.plan.joint_travel).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    field_validator,
    model_serializer,
)

from station.config.joint_reference import DEFAULT_REPEATS, DEFAULT_TARGETS, ReferenceConfig
from station.errors import BadInput, read_input

Joint = Literal["x", "y", "z"]
#: The keys of the station's own test and their defaults: left out of a dump that
#: has them so, a config without the test dumps as it did before the test existed.
STATION_DEFAULTS: dict[str, object] = {"station_test": [], "station_gauge": None,
                                       "station_repeats": DEFAULT_REPEATS,
                                       "station_targets": DEFAULT_TARGETS, "reference": None}
#: The columns of a test file: required, then optional.
COLUMNS = ("target_mm", "forward_um", "reverse_um")
OPTIONAL = ("u_um",)


class JointsConfig(BaseModel):
    """``[joints]``: ``tests`` maps a joint (any of x, y, z) to its ISO 230-2 test
    file, a path relative to the config's folder (made absolute as the config loads).
    ``station_test``: the joints the station tests itself against ``reference``
    (station.config.joint_reference), with the indicator ``station_gauge`` (one for
    all, or one per joint; None: the config's first), ``station_repeats`` approaches
    of each target from each side and, with gauge blocks, ``station_targets``
    targets."""

    model_config = ConfigDict(extra="forbid", validate_default=True)

    tests: dict[Joint, str] = Field(default_factory=dict)
    station_test: list[Joint] = Field(default_factory=list, max_length=3)
    station_gauge: str | dict[Joint, str] | None = None
    station_repeats: int = Field(DEFAULT_REPEATS, ge=2, le=20)
    station_targets: int = Field(DEFAULT_TARGETS, ge=5, le=50)
    reference: ReferenceConfig | None = None

    @field_validator("station_test")
    @classmethod
    def _once(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("a joint named twice")
        return value

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, object]:
        data = handler(self)
        for name, default in STATION_DEFAULTS.items():
            if name in data and getattr(self, name) == default:
                del data[name]
        return data

    def check_station_test(self, names: list[str]) -> None:
        """ValueError unless the station's own test has a reference and each of its
        joints a gauge among ``names`` (the config's indicators)."""
        if not self.station_test:
            return
        if self.reference is None:
            raise ValueError("joints.station_test: needs [joints.reference], the length "
                             "reference the station's gauge reads")
        if isinstance(self.station_gauge, dict):
            missing = [a for a in self.station_test if a not in self.station_gauge]
            if missing:
                raise ValueError(f"joints.station_gauge: no gauge for joint(s) "
                                 f"{', '.join(missing)} of station_test")
        for axis in self.station_test:
            gauge = self.gauge_of(axis, names[0])
            if gauge not in names:
                raise ValueError(f"joints.station_gauge: no indicator {gauge!r} "
                                 f"(have {', '.join(names)})")

    def gauge_of(self, axis: str, first: str) -> str:
        """The indicator that tests joint ``axis`` (``first``: the config's first)."""
        g = self.station_gauge
        if g is None:
            return first
        if isinstance(g, str):
            return g
        return next((name for joint, name in g.items() if joint == axis), first)

    @field_validator("tests")
    @classmethod
    def _paths(cls, value: dict[str, str]) -> dict[str, str]:
        for axis, path in value.items():
            if not path.strip():
                raise ValueError(f"{axis}: an empty path")
        return value


@dataclass(frozen=True)
class JointTest:
    """One joint's test as its file gives it: the targets (mm), the deviations
    approached in +ρ and in −ρ (µm), the expanded uncertainty per target (µm; None:
    not given), and the file's line of each row (what a later check names)."""

    source: str
    targets_mm: tuple[float, ...]
    forward_um: tuple[float, ...]
    reverse_um: tuple[float, ...]
    u_um: tuple[float, ...] | None
    lines: tuple[int, ...]


def _header(cells: list[str], where: str) -> dict[str, int]:
    names = [c.strip().lower() for c in cells]
    known = COLUMNS + OPTIONAL
    for name in names:
        if name not in known:
            raise BadInput(f"{where}: unknown column {name!r} (the header is "
                           f"{','.join(COLUMNS)} and optionally {','.join(OPTIONAL)})")
    if len(set(names)) != len(names):
        raise BadInput(f"{where}: a column is named twice")
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise BadInput(f"{where}: the header lacks {', '.join(missing)} (the header is "
                       f"{','.join(COLUMNS)} and optionally {','.join(OPTIONAL)})")
    return {name: i for i, name in enumerate(names)}


def _number(text: str, column: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise BadInput(f"{where}: {column} is not a number: {text.strip()!r}") from None
    if not math.isfinite(value):
        raise BadInput(f"{where}: {column} is not a finite number: {text.strip()!r}")
    return value


def parse_joint_test(text: str, source: str) -> JointTest:
    """The test in ``text`` (the file named ``source``); BadInput naming ``source`` and
    the line of the first bad row."""
    columns: dict[str, int] | None = None
    rows: dict[str, list[float]] = {c: [] for c in COLUMNS + OPTIONAL}
    lines: list[int] = []
    for n, line in enumerate(text.lstrip("\ufeff").splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{source}: line {n}"
        cells = next(csv.reader([line]))
        if columns is None:
            columns = _header(cells, where)
            continue
        if len(cells) != len(columns):
            raise BadInput(f"{where}: {len(cells)} values where the header names "
                           f"{len(columns)} ({','.join(columns)})")
        for name, i in columns.items():
            rows[name].append(_number(cells[i], name, where))
        if "u_um" in columns and rows["u_um"][-1] < 0:
            raise BadInput(f"{where}: u_um must be >= 0, got {rows['u_um'][-1]:g}")
        t = rows["target_mm"]
        if len(t) > 1 and not t[-1] > t[-2]:
            raise BadInput(f"{where}: target_mm {t[-1]:g} does not follow {t[-2]:g}: the "
                           "targets must be strictly increasing")
        lines.append(n)
    if columns is None:
        raise BadInput(f"{source}: empty: expected the header {','.join(COLUMNS)}")
    if len(lines) < 2:
        raise BadInput(f"{source}: {len(lines)} target(s): a test needs at least two")
    return JointTest(source, tuple(rows["target_mm"]), tuple(rows["forward_um"]),
                     tuple(rows["reverse_um"]),
                     tuple(rows["u_um"]) if "u_um" in columns else None, tuple(lines))


@lru_cache(maxsize=32)
def _read(path: str, stamp: tuple[int, int]) -> JointTest:
    del stamp  # part of the cache's key only: a file written again is read again
    return parse_joint_test(read_input(Path(path)), path)


def read_joint_test(path: str) -> JointTest:
    """The test in the file at ``path``; BadInput naming the file (and the line)."""
    try:
        st = os.stat(path)
    except OSError:
        read_input(Path(path))  # says why, in the station's words
        raise
    return _read(path, (st.st_mtime_ns, st.st_size))


def read_joint_tests(tests: Mapping[Joint, str]) -> dict[Joint, JointTest]:
    """Every test of ``[joints] tests`` (joint → path), read and parsed."""
    return {axis: read_joint_test(path) for axis, path in sorted(tests.items())}


def resolved(joints: JointsConfig, base_dir: Path) -> JointsConfig:
    """``joints`` with its tests' paths made absolute (relative ones are
    ``base_dir``'s), each test read and checked: BadInput naming the file and line."""
    tests: dict[Joint, str] = {
        axis: path if Path(path).is_absolute() else str((base_dir / path).resolve())
        for axis, path in joints.tests.items()}
    read_joint_tests(tests)
    return joints if tests == joints.tests else joints.model_copy(update={"tests": tests})
