"""What the station knows of each joint (station.analysis.joints.JointKnowledge): a
shop's test, the station's own table, or an assumed bound, named as assumed; the
measured lost motion winning over a table's reversal; result.json's ``joints``."""

from __future__ import annotations

import numpy as np
import pytest
from builders import station_data

import orthocal
from station.analysis import joints
from station.config import parse_config
from station.config.joint_tests import parse_joint_test
from station.record.result_joints import Joints

L = orthocal.Geometry().leg_length


def laser(k_um_per_m: float, offset_um: float = 3.0, reversal_um: float = 4.0,
          u: bool = True) -> str:
    """A test of a lead k with a constant (the laser zeroed elsewhere) and a reversal."""
    rows = ["target_mm,forward_um,reverse_um" + (",u_um" if u else "")]
    for t in range(170, 390, 10):
        e = offset_um + k_um_per_m * 1e-3 * (t - L)
        rows.append(f"{t},{e - reversal_um / 2:.4f},{e + reversal_um / 2:.4f}"
                    + (",0.5" if u else ""))
    return "\n".join(rows)


def config(**uncertainty: float):
    return parse_config(station_data(uncertainty=uncertainty))


def test_untested_joints_rest_on_the_assumed_bound_and_say_so() -> None:
    know = joints.joint_knowledge(config())
    assert know.sources() == {"x": "assumed", "y": "assumed", "z": "assumed"}
    assert not know.bound.given and know.bound.value == 170.0
    assert "ISO 3408-3 class C7" in (know.bound.assumed or "")
    for j in know.joints:
        assert j.table is None and j.bound_um_per_m == 170.0 and j.lead_um_per_m == 0.0
        assert j.lead_interval_95_um_per_m == pytest.approx((-161.5, 161.5))
    assert know.x.bound_mm(np.array([L - 100.0, L, L + 60.0])) == \
        pytest.approx([0.017, 0.0, 0.0102])
    (said,) = know.assumed
    assert said.startswith("joint(s) x, y, z: positioning within ±170 µm per metre")
    assert "assumed: a rolled ball screw" in said
    # every joint exact at its mean: the field of the joints is the bound's to state
    e = know.errors()
    assert (e.x, e.y, e.z) == (None, None, None)
    stated = joints.joint_knowledge(config(joint_positioning_um_per_m=120.0))
    assert stated.bound.given and stated.x.lead_interval_95_um_per_m == pytest.approx((-114, 114))
    assert "(stated)" in stated.assumed[0]


def test_a_shops_test_is_referred_to_pi0_with_its_lead_and_interval() -> None:
    test = parse_joint_test(laser(100.0), "/shop/x.csv")
    know = joints.joint_knowledge(config(), {"x": test})
    x = know.x
    assert x.source == "test" and x.file == "/shop/x.csv" and x.reversal_from == "test"
    assert x.table is not None
    assert x.table.error(L, "mean") == pytest.approx(0.0, abs=1e-15)
    assert x.table.shift_mm == pytest.approx(0.003)  # the laser's zero, Δρ's to take
    assert x.table.reversal_mm == pytest.approx([-0.004] * 22)
    assert x.lead_um_per_m == pytest.approx(100.0, abs=1e-6)
    lo, hi = x.lead_interval_95_um_per_m
    assert lo < 100.0 < hi and hi - 100.0 == pytest.approx(
        orthocal.lead_um_per_m(x.table).points_um_per_m)  # a pure lead: no scatter
    with pytest.raises(ValueError, match="has a table"):
        x.bound_mm(L)
    assert know.sources() == {"x": "test", "y": "assumed", "z": "assumed"}
    assert know.assumed[0].startswith("joint(s) y, z:")
    e = know.errors()
    assert e.x is x.table and e.y is None
    assert e.error(np.array([L + 50.0, L, L]))[0] == pytest.approx(0.005, abs=1e-12)
    # every joint tested: nothing assumed
    tests = {a: parse_joint_test(laser(k), f"{a}.csv")
             for a, k in zip("xyz", (100.0, -80.0, 60.0), strict=True)}
    all_tested = joints.joint_knowledge(config(), tests)
    assert all_tested.assumed == []
    assert [j.lead_um_per_m for j in all_tested.joints] == pytest.approx([100, -80, 60])


def test_the_stations_own_table_wins_over_a_shops() -> None:
    own = orthocal.lead_table(-75.0, (170.0, 380.0), L)
    know = joints.joint_knowledge(config(), {"y": parse_joint_test(laser(-80.0), "y.csv")},
                                  {"y": own})
    assert know.y.source == "station" and know.y.file is None
    assert know.y.lead_um_per_m == pytest.approx(-75.0)


def test_the_measured_reversal_wins_over_the_tables() -> None:
    know = joints.joint_knowledge(config(), {"x": parse_joint_test(laser(100.0), "x.csv"),
                                             "y": parse_joint_test(laser(-80.0), "y.csv")})
    measured = know.with_reversal({"x": 0.006, "y": -0.0004, "z": 0.003})
    assert measured.x.reversal_from == "station"
    assert measured.x.table is not None and know.x.table is not None
    assert measured.x.table.reversal_mm == pytest.approx([-0.006] * 22)
    assert measured.x.table.mean_mm == pytest.approx(know.x.table.mean_mm, abs=1e-15)
    # a negative B is noise about none; an assumed joint has no table to change
    assert measured.y.table is not None
    assert measured.y.table.reversal_mm == pytest.approx([0.0] * 22, abs=1e-15)
    assert measured.z == know.z
    # not measured: the test's own reversal stays
    assert know.with_reversal({"x": None}).x == know.x


def test_the_record_states_the_table_used_in_um() -> None:
    know = joints.joint_knowledge(
        config(joint_positioning_um_per_m=120.0),
        {"z": parse_joint_test(laser(60.0, u=False), "/shop/z.csv")}).with_reversal(
        {"z": 0.002})
    doc = joints.fields(know)
    assert isinstance(doc, Joints)
    back = Joints.model_validate_json(doc.model_dump_json())  # closed, typed, round trip
    z = back.z
    assert z.source == "test" and z.file == "/shop/z.csv" and z.table is not None
    assert z.table.reversal_from == "station" and z.table.u95_um is None
    assert z.table.targets_mm[:2] == [170.0, 180.0]
    assert np.subtract(z.table.forward_um, z.table.reverse_um) == pytest.approx([-2.0] * 22)
    assert z.table.shift_um == pytest.approx(3.0)
    assert z.table.forward_um[0] == pytest.approx(60e-3 * (170 - L) - 1.0)
    assert z.lead_um_per_m == pytest.approx(60.0)
    assert back.x.source == "assumed" and back.x.table is None
    assert back.x.bound_um_per_m == 120.0 and back.bound.given
    assert back.assumed and "Π0" in back.convention
