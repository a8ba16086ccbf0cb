"""The maths of the LinuxCNC kinematics component (orthocal/orthoglidekins.comp, the block
between its ``orthocal maths`` markers) against orthocal/kinematics.py: built with the
system's C compiler and called through ctypes, on random machines (leg lengths L ± 1 mm,
tilts ± 2 mrad, gaps ± 0.5 mm, Δρ ± 3 mm) over the workspace box [−100, 60]³ of the
paper's machine and beyond it, up to and past the legs' reach (docs/model.md, "Machine
and parameters", "Extended model", "Axes that do not meet")."""

from __future__ import annotations

import ctypes
import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from importlib import resources

import numpy as np
import pytest
from system import require

from orthocal.geometry import Geometry
from orthocal.kinematics import axis_directions, axis_origins, forward, inverse

L = 310.25
BOX = (-100.0, 60.0)
TOL = 1e-9  # mm
#: Joint values written into the output before a call: an error must leave them there.
UNTOUCHED = 1234.5
_BLOCK = re.compile(r"/\* orthocal maths: begin \*/(.*?)/\* orthocal maths: end \*/", re.S)
_D3 = ctypes.c_double * 3


class _CGeometry(ctypes.Structure):
    """struct og_geometry of the component."""

    _fields_ = [("leg_length", _D3), ("tilt", _D3), ("gap", _D3), ("drho", _D3)]


@dataclass(frozen=True)
class Machine:
    dL: np.ndarray
    tilt: np.ndarray
    gap: np.ndarray
    drho: np.ndarray

    def kwargs(self) -> dict[str, np.ndarray]:
        """orthocal.kinematics' arguments beside the geometry."""
        return {"drho": self.drho, "dL": self.dL, "tilt": self.tilt, "gap": self.gap}

    def c_struct(self) -> _CGeometry:
        return _CGeometry(_D3(*(L + self.dL)), _D3(*self.tilt), _D3(*self.gap),
                          _D3(*self.drho))


NOMINAL = Machine(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))


def random_machine(rng: np.random.Generator) -> Machine:
    return Machine(rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3), rng.uniform(-0.5, 0.5, 3),
                   rng.uniform(-3, 3, 3))


class Kins:
    """og_inverse and og_forward of the built block; None for an error, after checking
    that the error left the output as it was (never a pose, never a NaN joint)."""

    def __init__(self, library: ctypes.CDLL) -> None:
        self._lib = library

    def call(self, name: str, geometry: _CGeometry, values: np.ndarray) -> np.ndarray | None:
        out = _D3(*[UNTOUCHED] * 3)
        code = getattr(self._lib, name)(ctypes.byref(geometry),
                                        _D3(*np.asarray(values, dtype=float)), out)
        if code != 0:
            assert list(out) == [UNTOUCHED] * 3, f"{name} failed but wrote {list(out)}"
            return None
        result = np.array(out)
        assert np.isfinite(result).all(), f"{name} succeeded with {result}"
        return result

    def inverse(self, machine: Machine, p: np.ndarray) -> np.ndarray | None:
        return self.call("og_inverse", machine.c_struct(), p)

    def forward(self, machine: Machine, rho: np.ndarray) -> np.ndarray | None:
        return self.call("og_forward", machine.c_struct(), rho)


def maths_block() -> str:
    source = (resources.files("orthocal") / "orthoglidekins.comp").read_text(encoding="utf-8")
    match = _BLOCK.search(source)
    assert match, "orthoglidekins.comp has no orthocal maths markers"
    return match.group(1)


@pytest.fixture(scope="module")
def kins(tmp_path_factory: pytest.TempPathFactory) -> Kins:
    """The block built as a shared library, its two functions exported (OG_API empty
    instead of static), the caller providing <math.h> as the component's rtapi_math.h
    does; warnings are errors."""
    compiler = shutil.which(os.environ.get("CC", "cc"))
    require(compiler is not None, "a C compiler (cc, or $CC) to build the kinematics' maths")
    assert compiler is not None
    folder = tmp_path_factory.mktemp("kins_c")
    source, library = folder / "og_maths.c", folder / "og_maths.so"
    source.write_text("#include <math.h>\n#define OG_API\n" + maths_block(), encoding="utf-8")
    built = subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-Wall", "-Werror", "-o",
                            str(library), str(source), "-lm"],
                           capture_output=True, text=True, timeout=120, check=False)
    assert built.returncode == 0, built.stderr
    lib = ctypes.CDLL(str(library))
    for name in ("og_inverse", "og_forward"):
        getattr(lib, name).restype = ctypes.c_int
    return Kins(lib)


def python_inverse(machine: Machine, p: np.ndarray) -> np.ndarray | None:
    try:
        return inverse(p, Geometry(), **machine.kwargs())
    except ValueError:
        return None


def python_forward(machine: Machine, rho: np.ndarray) -> np.ndarray | None:
    try:
        with np.errstate(divide="ignore", invalid="ignore"):
            return forward(rho, Geometry(), **machine.kwargs())
    except ValueError:
        return None


def box_points(rng: np.random.Generator, n: int, margin: float = 0.0) -> np.ndarray:
    lo, hi = BOX[0] - margin, BOX[1] + margin
    corners = np.array(np.meshgrid([lo, hi], [lo, hi], [lo, hi])).reshape(3, -1).T
    return np.vstack([corners, rng.uniform(lo, hi, (n, 3))])


def test_the_maths_block_needs_nothing_of_linuxcnc() -> None:
    block = maths_block()
    assert "#include" not in block
    assert not re.search(r"\b(rtapi|hal_|EmcPose|KINEMATICS)\w*", block)


@pytest.mark.parametrize("seed", range(6))
def test_inverse_is_pythons_inside_the_reach_and_an_error_beyond(kins: Kins, seed: int) -> None:
    rng = np.random.default_rng(seed)
    machine = random_machine(rng)
    # the box, then a cube twice the legs' length across: most of it beyond some leg's reach
    points = np.vstack([box_points(rng, 300), rng.uniform(-2 * L, 2 * L, (600, 3))])
    refused = 0
    for p in points:
        want, got = python_inverse(machine, p), kins.inverse(machine, p)
        if want is None:
            assert got is None, f"C gives joints {got} for {p}, beyond a leg's reach"
            refused += 1
        else:
            assert got is not None, f"C refuses {p}, within reach (Python: {want})"
            np.testing.assert_allclose(got, want, rtol=0, atol=TOL)
    assert 100 < refused < len(points) - 300  # both sides of the reach were tried


@pytest.mark.parametrize("seed", range(6))
def test_forward_is_pythons_and_gives_the_point_back(kins: Kins, seed: int) -> None:
    # The box and 50 mm around it: the working assembly mode, where a point's joints
    # have that point as their forward kinematics (far beyond, the same joints may close
    # only the mirror image, test_forward_never_gives_a_wrong_pose).
    rng = np.random.default_rng(100 + seed)
    machine = random_machine(rng)
    for p in box_points(rng, 400, margin=50.0):
        rho = kins.inverse(machine, p)
        assert rho is not None
        want = python_forward(machine, rho)
        got = kins.forward(machine, rho)
        assert want is not None and got is not None, (p, rho, want, got)
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL)
        np.testing.assert_allclose(got, p, rtol=0, atol=TOL)  # the round trip IK -> FK


def test_nominal_values_are_the_papers_closed_form(kins: Kins) -> None:
    # model.md (1): ρ_i = p_i + sqrt(L² − p_j² − p_k²), and its forward closed form, here
    # written out again rather than taken from orthocal.kinematics.
    grid = np.linspace(*BOX, 7)
    for p in np.array(np.meshgrid(grid, grid, grid)).reshape(3, -1).T:
        rho = p + np.sqrt(L**2 - (p @ p - p**2))
        np.testing.assert_allclose(kins.inverse(NOMINAL, p), rho, rtol=0, atol=TOL)
        k, w = rho**2 - L**2, 1 / (4 * rho**2)
        a, b, c = w.sum(), 2 * (k * w).sum() - 1, (k**2 * w).sum()
        s = 2 * c / (-b + np.sqrt(b**2 - 4 * a * c))
        np.testing.assert_allclose(kins.forward(NOMINAL, rho), (s + k) / (2 * rho),
                                   rtol=0, atol=TOL)
        np.testing.assert_allclose(kins.forward(NOMINAL, rho), p, rtol=0, atol=TOL)


def _reach(machine: Machine, direction: np.ndarray) -> float:
    """How far from the origin along ``direction`` the legs reach (Python's inverse),
    to 1e-12 mm."""
    inside, outside = 0.0, 2.0 * (L + 1.0)  # every leg's cylinder has radius L_i < 2L
    while outside - inside > 1e-12:
        middle = (inside + outside) / 2
        if python_inverse(machine, middle * direction) is None:
            outside = middle
        else:
            inside = middle
    return inside


@pytest.mark.parametrize("seed", range(4))
def test_inverse_refuses_points_just_beyond_the_reach(kins: Kins, seed: int) -> None:
    # Both sides of the bound, along rays that leave the workspace every way: a micrometre
    # inside, the C gives Python's joints (sqrt is steep there); a micrometre out, an error.
    rng = np.random.default_rng(200 + seed)
    machine = random_machine(rng)
    rays = rng.normal(size=(10, 3))
    for direction in np.vstack([rays, -rays, np.eye(3), -np.eye(3)]):
        direction = direction / np.linalg.norm(direction)
        edge = _reach(machine, direction)
        inside = (edge - 1e-6) * direction
        got = kins.inverse(machine, inside)
        assert got is not None, f"C refuses {inside}, within reach"
        np.testing.assert_allclose(got, python_inverse(machine, inside), rtol=0, atol=TOL)
        assert kins.inverse(machine, (edge + 1e-6) * direction) is None


@pytest.mark.parametrize("seed", range(3))
def test_forward_refuses_joints_outside_the_assembly_domain(kins: Kins, seed: int) -> None:
    rng = np.random.default_rng(300 + seed)
    machine = random_machine(rng)
    zero = kins.inverse(machine, np.zeros(3))  # the mechanical zero Π0
    assert zero is not None
    bad = [zero + np.array([f, f, f]) for f in (np.nan, np.inf, -np.inf, 1e12, -1e12)]
    for i in range(3):
        e = np.eye(3)[i]
        # a carriage so far out that its leg cannot meet the others', Python agrees
        assert python_forward(machine, zero + 2 * L * e) is None
        bad += [zero + 2 * L * e, zero + 1e12 * e, zero + np.nan * e]
        # the other side: a carriage a leg's length behind the origin, its leg cannot
        # reach the others' in the working mode (the carriage beyond P)
        bad += [zero - 2 * L * e, zero - 1e12 * e]
    bad += [zero + 2 * L, zero - 2 * L]  # every carriage out, every carriage in
    for rho in bad:
        assert kins.forward(machine, rho) is None, f"C gives a pose for joints {rho}"


@pytest.mark.parametrize("seed", range(4))
def test_forward_never_gives_a_wrong_pose(kins: Kins, seed: int) -> None:
    # Joints anywhere within ±400 mm of the mechanical zero: whatever pose the C gives
    # closes every leg (1'), in the working assembly mode (the legs' volume of opposite
    # sign to its mirror's), and the inverse takes it back to the same joints.
    rng = np.random.default_rng(400 + seed)
    machine = random_machine(rng)
    zero = kins.inverse(machine, np.zeros(3))
    assert zero is not None
    u, c = axis_directions(machine.tilt), axis_origins(machine.gap)
    legs = L + machine.dL
    given = 0
    for rho in zero + rng.uniform(-400, 400, (1500, 3)):
        p = kins.forward(machine, rho)
        if p is None:
            continue
        given += 1
        d = p - c - (rho + machine.drho)[:, None] * u  # rows P − A_i
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), legs, rtol=0, atol=TOL)
        assert np.linalg.det(d) < 0
        np.testing.assert_allclose(kins.inverse(machine, p), rho, rtol=0, atol=TOL)
    assert 200 < given < 1400  # joints in the domain and beyond it were tried


@pytest.mark.parametrize("field", ["leg_length", "tilt", "gap", "drho"])
def test_a_geometry_not_finite_gives_nothing(kins: Kins, field: str) -> None:
    machine = random_machine(np.random.default_rng(5))
    zero = kins.inverse(machine, np.zeros(3))
    assert zero is not None
    broken = machine.c_struct()
    getattr(broken, field)[1] = np.nan
    assert kins.call("og_inverse", broken, np.zeros(3)) is None
    assert kins.call("og_forward", broken, zero) is None

