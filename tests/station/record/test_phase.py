"""A pass's phase, read in one place (station.record.phase): every name round-trips, and
every reader agrees on "m+1" (a first measurement measured again)."""

from __future__ import annotations

import pytest

from station.engine.sizing import verifies
from station.record.phase import Phase, phase_of


@pytest.mark.parametrize(("text", "rnd", "extra"), [
    ("m", 0, 0), ("v", 1, 0), ("v2", 2, 0), ("v+1", 1, 1), ("v2+1", 2, 1), ("m+1", 0, 1),
    ("v13+2", 13, 2)])
def test_every_phase_round_trips(text: str, rnd: int, extra: int) -> None:
    phase = Phase.parse(text)
    assert (phase.round, phase.extra) == (rnd, extra)
    assert str(phase) == text == phase_of(rnd, extra)


@pytest.mark.parametrize("text", ["", "x", "v0", "m2", "v+", "+1", "v-1", "vv", "m+1+1"])
def test_what_is_no_phase_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match="not a phase"):
        Phase.parse(text)


def test_a_recheck_pass_is_a_measurement_sized_like_a_verification() -> None:
    again = Phase.parse("m+1")
    assert again.kind == "measurement" and not again.verifies
    assert again.sized_like_verification and verifies("m+1")
    assert not verifies("m") and verifies("v") and verifies("v2+1")
    assert again.first_pass == Phase.parse("m")
    assert again.label == "measure, again (1)"
    assert Phase.parse("v2+1").label == "verify 2, again (1)"
