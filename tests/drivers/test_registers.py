"""Register maps as data (drivers.registers): profiles, overrides, integer codecs."""

from __future__ import annotations

import pytest

from drivers.map_files import builtin_maps, load_map
from drivers.registers import (
    GENERIC,
    RegisterMap,
    RegisterMapError,
    contiguous_runs,
    decode_i32,
    decode_int,
    encode_i32,
    encode_int,
    to_counts,
    um_to_mm,
)

IAI_PCON = builtin_maps()["iai-pcon-direct"]

# docs/design.md's table, written out independently of the code under test.
DESIGN_TABLE = {
    "COMMAND": (0, "u16", "W"), "STATUS": (1, "u16", "R"), "ALARM_CODE": (2, "u16", "R"),
    "TARGET_X": (10, "i32", "RW"), "TARGET_Y": (12, "i32", "RW"), "TARGET_Z": (14, "i32", "RW"),
    "ACTUAL_X": (20, "i32", "R"), "ACTUAL_Y": (22, "i32", "R"), "ACTUAL_Z": (24, "i32", "R"),
    "OFFSET_X": (30, "i32", "RW"), "OFFSET_Y": (32, "i32", "RW"), "OFFSET_Z": (34, "i32", "RW"),
    "SPEED": (40, "u16", "RW"),
    "SOFT_MIN_X": (50, "i32", "R"), "SOFT_MIN_Y": (52, "i32", "R"), "SOFT_MIN_Z": (54, "i32", "R"),
    "SOFT_MAX_X": (60, "i32", "R"), "SOFT_MAX_Y": (62, "i32", "R"), "SOFT_MAX_Z": (64, "i32", "R"),
}


def test_generic_profile_matches_design_table() -> None:
    m = load_map("orthocal-generic")
    assert sorted(m.names()) == sorted(DESIGN_TABLE)
    for name, (address, reg_type, access) in DESIGN_TABLE.items():
        reg = m[name]
        assert (reg.address, reg.type, reg.access, reg.table) == (address, reg_type, access,
                                                                  "holding"), name
        assert reg.word_order == "high_first"
        assert reg.device_id is None
    for role in ("TARGET", "ACTUAL", "OFFSET", "SOFT_MIN", "SOFT_MAX"):
        assert all(r.scale == 1000.0 for r in m.axis_registers(role)), role  # µm
    bits = {flag: (spec.registers, spec.bit) for flag, spec in m.status.items()}
    assert bits == {"homed": (["STATUS"], 0), "moving": (["STATUS"], 1),
                    "in_position": (["STATUS"], 2), "alarm": (["STATUS"], 3),
                    "estop": (["STATUS"], 4)}
    assert {c: m.command_code(c) for c in m.commands} == {
        "move": 1, "stop": 2, "home": 3, "reset_alarm": 4}
    assert m.alarm_code == ["ALARM_CODE"]
    assert "o_i ← o_i − Δρ_i" in m.offset_convention


def test_iai_profile_one_device_per_axis_and_no_offsets() -> None:
    m = load_map("iai-pcon-direct")
    assert [r.device_id for r in m.axis_registers("TARGET")] == [1, 2, 3]
    assert {r.address for r in m.axis_registers("TARGET")} == {0x9900}
    assert {r.address for r in m.axis_registers("ACTUAL")} == {0x9000}
    assert all(r.scale == 100.0 for r in m.axis_registers("ACTUAL"))  # 0.01 mm
    assert m["HOME_X"].table == "coil" and m["HOME_X"].address == 0x040B
    assert m.commands["move"] == []  # writing PCMD starts the move
    assert not m.has_role("OFFSET") and "offset" in m.unsupported["offsets"]
    assert m.status["estop"].bit == 15 and m.status["homed"].combine == "all"


def test_builtin_profiles_are_listed() -> None:
    maps = builtin_maps()
    assert {"orthocal-generic", "iai-pcon-direct"} <= set(maps)
    assert all(name == m.name for name, m in maps.items())
    assert load_map(GENERIC) is GENERIC and load_map(IAI_PCON) is IAI_PCON


def test_override_moves_one_entry_only() -> None:
    m = load_map("orthocal-generic", {"OFFSET_X": {"address": 130}})
    assert m["OFFSET_X"].address == 130
    assert m["OFFSET_Y"].address == 32
    assert GENERIC["OFFSET_X"].address == 30  # the built-in is untouched
    m2 = load_map("orthocal-generic", {"ACTUAL_X": {"word_order": "low_first", "scale": 100}})
    assert (m2["ACTUAL_X"].word_order, m2["ACTUAL_X"].scale) == ("low_first", 100.0)


@pytest.mark.parametrize(
    ("overrides", "named", "says"),
    [
        ({"OFFSET_Q": {"address": 1}}, "OFFSET_Q", "no such register"),
        ({"OFFSET_X": {"adress": 130}}, "OFFSET_X", "adress"),
        ({"OFFSET_X": {"address": -1}}, "OFFSET_X", "address"),
        ({"OFFSET_X": {"type": "f64"}}, "OFFSET_X", "type"),
        ({"OFFSET_X": {"scale": 0}}, "OFFSET_X", "scale"),
        ({"OFFSET_X": 130}, "OFFSET_X", "table of fields"),
        ({"OFFSET_X": {"name": "OFFSET_Q"}}, "OFFSET_X", "rename"),
        ({"OFFSET_X": {"address": 11}}, "OFFSET_X", "overlap"),
    ],
)
def test_bad_override_names_the_entry(overrides: dict, named: str, says: str) -> None:
    with pytest.raises(RegisterMapError) as info:
        load_map("orthocal-generic", overrides)
    assert named in str(info.value)
    assert says in str(info.value)


def test_unknown_profile_is_named() -> None:
    with pytest.raises(RegisterMapError, match=r"'nope'.*orthocal-generic"):
        load_map("nope")


def test_map_validation_catches_missing_roles() -> None:
    data = GENERIC.model_dump()
    data["registers"] = [r for r in data["registers"] if r["name"] != "ACTUAL_Y"]
    with pytest.raises(ValueError, match="ACTUAL_Y"):
        RegisterMap.model_validate(data)
    data = GENERIC.model_dump()
    data["registers"] = [r for r in data["registers"] if not r["name"].startswith("OFFSET")]
    with pytest.raises(ValueError, match="offsets"):
        RegisterMap.model_validate(data)
    data = GENERIC.model_dump() | {"colour": "red"}
    with pytest.raises(ValueError, match="colour"):
        RegisterMap.model_validate(data)


@pytest.mark.parametrize(
    ("value", "words"),
    [
        (0, [0x0000, 0x0000]),
        (1, [0x0000, 0x0001]),
        (-1, [0xFFFF, 0xFFFF]),
        (310250, [0x0004, 0xBBEA]),
        (-100000, [0xFFFE, 0x7960]),
        (0x7FFF_FFFF, [0x7FFF, 0xFFFF]),
        (-0x8000_0000, [0x8000, 0x0000]),
    ],
)
def test_i32_two_complement_high_word_first(value: int, words: list[int]) -> None:
    assert encode_i32(value) == words
    assert decode_i32(words) == value
    assert encode_i32(value, "low_first") == words[::-1]
    assert decode_i32(words[::-1], "low_first") == value


def test_int_ranges_and_16_bit_types() -> None:
    assert encode_int(-2, "i16") == [0xFFFE] and decode_int([0xFFFE], "i16") == -2
    assert decode_int([0xFFFE], "u16") == 0xFFFE
    assert decode_int([0xFFFF, 0xFFFF], "u32") == 0xFFFF_FFFF
    for bad, reg_type in [(0x8000_0000, "i32"), (-1, "u32"), (0x10000, "u16"), (-0x8001, "i16")]:
        with pytest.raises(ValueError):
            encode_int(bad, reg_type)
    with pytest.raises(ValueError):
        decode_int([1], "i32")
    with pytest.raises(ValueError):
        decode_int([0x10000, 0], "i32")


@pytest.mark.parametrize(
    ("mm", "um"),
    [(0.0029, 3), (0.0021, 2), (0.0005, 1), (-0.0005, -1), (-0.0029, -3), (1.0005, 1001),
     (310.25, 310250), (-100.0004, -100000), (0.0015, 2), (-0.0015, -2)],
)
def test_um_rounding_never_truncates(mm: float, um: int) -> None:
    assert to_counts(mm, 1000.0) == um


def test_register_encode_decode_in_mm() -> None:
    reg = GENERIC["TARGET_X"]
    assert reg.encode(-99.9996) == encode_i32(-100000)
    assert reg.decode(encode_i32(-123456)) == pytest.approx(-123.456, abs=1e-12)
    assert um_to_mm(310250) == pytest.approx(310.25, abs=1e-12)
    with pytest.raises(ValueError, match="TARGET_X"):
        reg.encode(3.0e6)  # 3e9 µm does not fit in i32
    with pytest.raises(ValueError):
        reg.encode(float("nan"))


def test_contiguous_runs_group_by_device_and_gap() -> None:
    runs = contiguous_runs(GENERIC.axis_registers("ACTUAL"))
    assert [(r[0], r[1], r[2], r[3]) for r in runs] == [(None, "holding", 20, 6)]
    status = contiguous_runs([GENERIC["STATUS"], GENERIC["ALARM_CODE"]])
    assert [(r[2], r[3]) for r in status] == [(1, 2)]
    both = GENERIC.axis_registers("SOFT_MIN") + GENERIC.axis_registers("SOFT_MAX")
    limits = contiguous_runs(both)
    assert sorted((r[2], r[3]) for r in limits) == [(50, 6), (60, 6)]
    merged = contiguous_runs(both, max_gap=4)
    assert [(r[2], r[3]) for r in merged] == [(50, 16)]
    iai = contiguous_runs(IAI_PCON.axis_registers("ACTUAL"))
    assert sorted((r[0], r[2], r[3]) for r in iai) == [(1, 0x9000, 2), (2, 0x9000, 2),
                                                        (3, 0x9000, 2)]
