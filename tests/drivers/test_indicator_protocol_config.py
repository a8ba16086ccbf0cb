"""Indicator protocols as a config gives them: a built-in with some keys
overridden keeps the rest; overrides that no gauge could speak are refused,
naming what is wrong (the bytes themselves: test_indicators_protocol.py)."""

from __future__ import annotations

from typing import Any

import pydantic
import pytest

from drivers.indicator_protocols import BUILTIN_PROTOCOLS, make_protocol


def test_generic_inch_gauge() -> None:
    proto = make_protocol("generic", {"unit": "in"})
    assert proto.mm_per_unit == 25.4


def test_overrides_keep_the_rest_of_a_builtin() -> None:
    proto = make_protocol("sylvac", {"baudrate": 9600})
    assert proto.baudrate == 9600
    assert proto.request == b"?\r" and proto.parity == "E"
    assert proto.reply_format == BUILTIN_PROTOCOLS["sylvac"].reply_format


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        ({"requets": "?\r"}, "requets"),
        ({"reply_pattern": r"(\d+)\.(\d+)"}, "exactly one group"),
        ({"reply_pattern": r"([0-9"}, "invalid regular expression"),
        ({"error_pattern": r"(E)(\d)"}, "at most one group"),
        ({"request": ""}, "empty"),
        ({"parity": "X"}, "parity"),
        ({"baudrate": 0}, "baudrate"),
        ({"reply_format": "{value:.3f} in"}, "reply_pattern does not match"),
        ({"error_format": "E{code}"}, "error_format needs an error_pattern"),
    ],
)
def test_bad_protocol_overrides_are_refused(overrides: dict[str, Any], words: str) -> None:
    with pytest.raises(pydantic.ValidationError, match=words):
        make_protocol("generic", overrides)


def test_unknown_protocol_names_the_known_ones() -> None:
    with pytest.raises(ValueError, match=r"unknown indicator protocol 'keyence'.*mitutoyo"):
        make_protocol("keyence")
