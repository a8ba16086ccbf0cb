"""Station config: the example loads, and every class of bad input is one
BadInput line naming the file and the field (or the TOML line)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from station.config import StationConfig, load_config
from station.config.toml import dump_toml
from station.errors import BadInput

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "station.toml"

MINIMAL = """
[[indicators]]
name = "A"
port = "/dev/ttyUSB0"

[[indicators]]
name = "B"
port = "/dev/ttyUSB1"
stroke_mm = 10.0

[[setups]]
leg = "x"
indicators = { A = "y", B = "-z" }
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "station.toml"
    path.write_text(text)
    return path


def error_of(tmp_path: Path, text: str) -> str:
    path = write(tmp_path, text)
    with pytest.raises(BadInput) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith(str(path) + ": ")
    assert "\n" not in message
    return message[len(str(path)) + 2:]


def test_example_loads_with_six_indicators_two_per_setup() -> None:
    config = load_config(EXAMPLE)
    assert len(config.indicators) == 6
    assert [len(s.indicators) for s in config.setups] == [2, 2, 2]
    assert config.setups[1].indicators["D"] == "-z"
    assert config.indicator("C").preload == 6.0


def test_defaults_preload_is_half_the_stroke(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, MINIMAL))
    assert config.indicator("A").preload == pytest.approx(12.5 / 2)
    assert config.indicator("B").preload == pytest.approx(5.0)
    assert config.procedure.cycles == 3 and config.writeback.max_abs_offset_mm == 3.0


def test_station_operator_is_read_and_absent_by_default(tmp_path: Path) -> None:
    assert load_config(write(tmp_path, MINIMAL)).station.operator is None
    named = load_config(write(tmp_path, '[station]\noperator = "J. Smith"\n' + MINIMAL))
    assert named.station.operator == "J. Smith"
    again = StationConfig.model_validate(tomllib.loads(dump_toml(named)))
    assert again.station.operator == "J. Smith"


def test_dump_round_trips(tmp_path: Path) -> None:
    config = load_config(EXAMPLE)
    again = StationConfig.model_validate(tomllib.loads(dump_toml(config)))
    assert again == config


@pytest.mark.parametrize(
    ("patch", "field", "says"),
    [
        # out of range
        ("[[indicators]]\nname='C'\nport='p'\nstroke_mm = 0\n", "indicators[2].stroke_mm",
         "must be > 0"),
        ("[procedure]\ncycles = 0\n", "procedure.cycles", "must be >= 1"),
        ("[controller]\nport = 70000\n", "controller.port", "1..65535"),
        ("[[indicators]]\nname='C'\nport='p'\npreload_mm = 20\n",
         "indicators[2].preload_mm", "<= stroke_mm"),
        # unknown key
        ("[procedure]\ncylces = 3\n", "procedure.cylces", "unknown key"),
        ("[extra]\na = 1\n", "extra", "unknown key"),
        ("[station]\noperater = 'J. Smith'\n", "station.operater", "unknown key"),
        ("[station]\noperator = ''\n", "station.operator", "at least 1"),
        # wrong type
        ("[procedure]\nreadings = 'five'\n", "procedure.readings", "valid integer"),
        ("[controller]\nport = true\n", "controller.port", "port number"),
        # wrong choice
        ("[[indicators]]\nname='C'\nport='p'\nprotocol='heidenhain'\n",
         "indicators[2].protocol", "mitutoyo"),
        ("[controller]\ntransport = 'rtu'\nport = 502\n", "controller.port", "serial device"),
        ("[[indicators]]\nname='C'\nport='p'\nprotocol='generic'\n",
         "indicators[2].pattern", "required"),
        ("[[indicators]]\nname='C'\nport='p'\nprotocol='generic'\nrequest='?'\n"
         "baudrate=9600\npattern='(a)(b)'\n", "indicators[2].pattern", "one group"),
    ],
)
def test_bad_values_name_their_field(tmp_path: Path, patch: str, field: str, says: str) -> None:
    message = error_of(tmp_path, MINIMAL + patch)
    assert message.startswith(field + ": "), message
    assert says in message


def test_setup_direction_must_differ_from_leg(tmp_path: Path) -> None:
    text = MINIMAL.replace('A = "y"', 'A = "x"')
    assert error_of(tmp_path, text).startswith("setups[0].indicators.A: direction must differ")


def test_setup_names_must_exist(tmp_path: Path) -> None:
    text = MINIMAL + '\n[[setups]]\nleg = "y"\nindicators = { Q = "x" }\n'
    message = error_of(tmp_path, text)
    assert message.startswith("setups[1].indicators.Q: no indicator of that name")


def test_duplicate_indicator_names(tmp_path: Path) -> None:
    text = MINIMAL + '\n[[indicators]]\nname = "A"\nport = "/dev/x"\n'
    assert error_of(tmp_path, text).startswith("indicators[2].name: duplicate")


def test_not_toml_names_the_line(tmp_path: Path) -> None:
    text = MINIMAL + "\n[procedure\ncycles = 3\n"
    message = error_of(tmp_path, text)
    line = text.count("\n", 0, text.index("[procedure")) + 1
    assert "not valid TOML" in message and f"line {line}" in message


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="no such file"):
        load_config(tmp_path / "nope.toml")


def test_missing_required_table(tmp_path: Path) -> None:
    text = MINIMAL.split("[[setups]]")[0]
    assert error_of(tmp_path, text).startswith("setups: missing")


GENERIC_UM = """
[[indicators]]
name = "G"
port = "{port}"
protocol = "generic"
baudrate = 9600
request = "R\\r"
terminator = "\\r"
pattern = '([+-]\\d+) um'
error_pattern = 'E(\\d+)'
unit = "um"
scale = {scale}

[[setups]]
leg = "x"
indicators = {{ G = "y" }}
"""


@pytest.mark.parametrize("scale", [1.0, -1.0])
def test_generic_gauge_units_and_errors_reach_the_driver(tmp_path: Path, scale: float) -> None:
    """A gauge reporting whole µm (counting either way) and its own error replies,
    configured by TOML fields alone, read through a real pty."""
    from drivers.device_errors import IndicatorReplyError
    from drivers.indicator_protocols import make_protocol
    from drivers.sim.faults import IndicatorFaults
    from drivers.sim.pty_gauges import SimIndicator
    from station.engine.devices import build_indicators

    wire = make_protocol("generic", {
        "baudrate": 9600, "request": "R\r", "terminator": "\r",
        "reply_pattern": r"([+-]\d+) um", "reply_format": "{value:+.0f} um",
        "error_pattern": r"E(\d+)", "error_format": "E{code}", "unit": "um",
    })  # fmt: skip
    position = {"mm": 0.0}
    faults = IndicatorFaults()
    with SimIndicator(wire, lambda: position["mm"], resolution_mm=0.001, zero_mm=0.0,
                      faults=faults, seed=1) as sim:  # fmt: skip
        config = load_config(write(tmp_path, GENERIC_UM.format(port=sim.port, scale=scale)))
        with build_indicators(config, None, None) as group:
            position["mm"] = 0.123  # the simulated gauge sends "+123 um"
            assert group.read(1)["G"] == [pytest.approx(0.123 * scale)]
            faults.error_next = 10  # more than the retries: the gauge's own error
            with pytest.raises(IndicatorReplyError, match="error"):
                group.read(1)


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("error_pattern = '(E)(\\d+)'", "at most one group"),
        ("scale = 0.0", "other than 0"),
        ('unit = "furlong"', "unit"),
    ],
)
def test_generic_gauge_fields_are_checked(tmp_path: Path, line: str, expected: str) -> None:
    text = GENERIC_UM.format(port="/dev/null", scale=1.0)
    key = line.split(" = ")[0]
    text = "\n".join(ln for ln in text.splitlines() if not ln.startswith(f"{key} ="))
    text = text.replace('protocol = "generic"', f'protocol = "generic"\n{line}')
    message = error_of(tmp_path, text)
    assert "indicators[0]" in message and expected in message
