"""Register maps as files (drivers.map_files; docs/design.md "Register-map files"):
every built-in map round-trips through TOML, a user's file loads from the
config's folder, and a bad file is refused naming the file and the entry
(exit 2, one line, before anything moves)."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.map_files import (
    MAPS_DIR,
    builtin_maps,
    load_map,
    map_from_toml,
    map_to_toml,
    read_map,
    resolve_map,
)
from drivers.registers import GENERIC, RegisterMap, RegisterMapError
from station.commands.cli import main
from station.config import load_config
from station.errors import BadInput

SHIPPED = sorted(p.stem for p in MAPS_DIR.glob("*.toml"))


def test_the_shipped_map_files_are_built_in() -> None:
    # The three drive families ship as data beside the generic map.
    assert {"iai-pcon-direct", "oriental-az-direct", "kinco-fd-cia402-modbus"} <= set(SHIPPED)
    maps = builtin_maps()
    assert set(maps) == {GENERIC.name, *SHIPPED}  # each file is named as its map
    for name, m in maps.items():
        assert m.name == name


@pytest.mark.parametrize("name", sorted(builtin_maps()))
def test_every_builtin_map_dumps_and_loads_back_identical(name: str, tmp_path: Path) -> None:
    m = builtin_maps()[name]
    text = map_to_toml(m, header=f"# {name}, dumped by the test")
    assert map_from_toml(text) == m
    path = tmp_path / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    back = read_map(path)
    assert back == m
    assert back.model_dump() == m.model_dump()  # field by field, descriptions included
    # ... and dumping the loaded map writes the same file again.
    assert map_to_toml(back, header=f"# {name}, dumped by the test") == text


def test_the_shipped_files_hold_no_field_the_model_drops() -> None:
    # A shipped file is exactly its model: what it says is what the station uses.
    import tomllib

    for path in MAPS_DIR.glob("*.toml"):
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
        assert RegisterMap.model_validate(raw).model_dump(exclude_defaults=True).keys() <= \
            raw.keys(), path.name


def test_maps_without_writable_offsets_say_why_and_what_to_do() -> None:
    for name in ("iai-pcon-direct", "oriental-az-direct", "kinco-fd-cia402-modbus"):
        m = builtin_maps()[name]
        assert not m.has_role("OFFSET"), name
        assert len(m.unsupported["offsets"]) > 40, name  # a reason, not a placeholder
    kinco = builtin_maps()["kinco-fd-cia402-modbus"]
    # 607Ch is there to read (probe shows it), never written by the station.
    assert all(kinco[f"HOME_OFFSET_{a}"].access == "R" for a in "XYZ")
    assert kinco["TARGET_X"].word_order == "low_first"  # Kinco: low word first


def test_command_values_are_encoded_by_the_register_type() -> None:
    oriental = builtin_maps()["oriental-az-direct"]
    accel = [s for s in oriental.commands["move"] if s.reg == "ACCEL_X"]
    assert accel and accel[0].value == 1_000_000  # an i32 rate, beyond one word
    data = GENERIC.model_dump()
    data["commands"]["move"] = [{"reg": "COMMAND", "value": 70_000}]  # COMMAND is u16
    with pytest.raises(ValueError, match=r"COMMAND.*u16"):
        RegisterMap.model_validate(data)


def _generic_text() -> str:
    return map_to_toml(GENERIC)


@pytest.mark.parametrize(
    ("edit", "says"),
    [
        # (old, new) in the generic map's text, and what the error must say
        (('name = "TARGET_Y"\naddress = 12\ntype = "i32"',
          'name = "TARGET_Y"\naddress = 12\ntype = "f64"'),
         "registers[4] (TARGET_Y): type:"),
        (('name = "ACTUAL_Z"\naddress = 24', 'name = "ACTUAL_Z"\naddress = -24'),
         "(ACTUAL_Z): address:"),
        (('name = "SPEED"\naddress = 40', 'name = "SPEED"\nadress = 40'),
         "(SPEED): adress: Extra inputs"),  # the typo, not only the missing field
        (('merge_gap = 0', 'merge_gap = 0\ncolour = "red"'), "colour"),
        (('bit = 2\n', 'bit = 17\n'), "status: in_position.bit:"),
        (('name = "TARGET_Z"', 'name = "TARGET_Q"'), "missing register TARGET_Z"),
        (('{reg = "COMMAND", value = 2}', '{reg = "COMAND", value = 2}'),
         "unknown register COMAND"),
    ],
)
def test_a_bad_map_file_names_the_file_and_the_entry(edit: tuple[str, str], says: str,
                                                      tmp_path: Path) -> None:
    old, new = edit
    text = _generic_text()
    assert old in text, old  # the edit applies to the file as written
    path = tmp_path / "acme-ls3.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(RegisterMapError) as info:
        read_map(path)
    message = str(info.value)
    assert message.startswith("acme-ls3.toml: "), message
    assert says in message, message
    assert "\n" not in message


def test_not_toml_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text('name = "x"\nmotion = coordinated\nmerge_gap = 0\n', encoding="utf-8")
    with pytest.raises(RegisterMapError, match=r"broken\.toml: .*line"):
        read_map(path)


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(RegisterMapError, match=r"gone\.toml: cannot read"):
        resolve_map(str(tmp_path / "gone.toml"))
    with pytest.raises(RegisterMapError, match=r"'acme'.*unknown register map.*\.toml"):
        resolve_map("acme")


def _config_text(profile: str) -> str:
    return (f'[controller]\nhost = "127.0.0.1"\nport = 1502\nprofile = "{profile}"\n\n'
            '[[indicators]]\nname = "A"\nport = "/dev/a"\n\n'
            '[[setups]]\nleg = "x"\nindicators = { A = "y" }\n')


def test_a_relative_map_path_is_the_configs_folder(tmp_path: Path, monkeypatch) -> None:
    maps = tmp_path / "rig" / "maps"
    maps.mkdir(parents=True)
    m = GENERIC.model_copy(update={"name": "acme-ls3"})
    (maps / "acme.toml").write_text(map_to_toml(m), encoding="utf-8")
    (tmp_path / "rig" / "station.toml").write_text(_config_text("maps/acme.toml"))
    monkeypatch.chdir(tmp_path)  # not the config's folder
    config = load_config(tmp_path / "rig" / "station.toml")
    assert Path(config.controller.profile) == (maps / "acme.toml").resolve()
    assert load_map(config.controller.profile).name == "acme-ls3"


def test_overrides_apply_to_a_map_file(tmp_path: Path) -> None:
    path = tmp_path / "acme.toml"
    path.write_text(map_to_toml(GENERIC.model_copy(update={"name": "acme"})))
    m = load_map(str(path), {"OFFSET_X": {"address": 130}})
    assert (m.name, m["OFFSET_X"].address, m["OFFSET_Y"].address) == ("acme", 130, 32)


def test_a_bad_map_in_the_config_is_bad_input_naming_both(tmp_path: Path) -> None:
    text = _generic_text().replace('name = "SPEED"\naddress = 40', 'name = "SPEED"\naddress = 11')
    (tmp_path / "acme.toml").write_text(text)
    (tmp_path / "station.toml").write_text(_config_text("acme.toml"))
    with pytest.raises(BadInput) as info:
        load_config(tmp_path / "station.toml")
    message = str(info.value)
    assert "station.toml" in message and "acme.toml" in message
    assert "overlap" in message


def test_run_with_a_bad_map_exits_2_in_one_line(tmp_path: Path, capsys) -> None:
    text = _generic_text().replace('type = "u16"', 'type = "u8"', 1)
    (tmp_path / "acme.toml").write_text(text)
    (tmp_path / "station.toml").write_text(_config_text("acme.toml"))
    code = main(["run", "--config", str(tmp_path / "station.toml"), "--yes",
                 "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "acme.toml: registers[0] (COMMAND): type:" in lines[0]
    assert "Traceback" not in err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())
