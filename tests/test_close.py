"""The tolerance of close.py: what another CPU changes passes, what a change of
behaviour changes does not."""

from __future__ import annotations

from close import differences, text_differences


def test_last_bits_pass_and_a_changed_figure_does_not() -> None:
    before = {"drho_x": 1.1013359004126901, "se": 0.0013645325657164226, "n": 3,
              "lo": 1.819472810772778e-05, "model": "rho", "ok": True}
    machine = {**before, "drho_x": 1.1013359004210772, "se": 0.0013645325717015176,
               "lo": 1.8191967141128768e-05}
    assert differences(machine, before) == []
    for key, value in (("drho_x", 1.1013459), ("se", 0.001366), ("n", 4),
                       ("lo", 1.9e-05 + 2e-7), ("model", "rho+tilt"), ("ok", False)):
        assert differences({**before, key: value}, before), key
    assert differences({**before, "extra": 1}, before)
    assert differences([1.0, 2.0], [1.0])
    assert differences(True, 1) and differences(1, 1.0) == []


def test_printed_text_allows_one_unit_of_the_last_digit_and_no_more() -> None:
    before = "Δρ_x +1.1013 mm after 3 cycles; path M 37.976752 12.5"
    assert text_differences("Δρ_x +1.1014 mm after 3 cycles; path M 37.976753 12.5",
                            before) == []
    assert text_differences("Δρ_x +1.1015 mm after 3 cycles; path M 37.976752 12.5", before)
    assert text_differences("Δρ_x +1.1013 mm after 4 cycles; path M 37.976752 12.5", before)
    assert text_differences("Δρ_y +1.1013 mm after 3 cycles; path M 37.976752 12.5", before)
