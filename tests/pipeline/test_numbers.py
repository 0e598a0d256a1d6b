"""Numbers for people: a value to its sigma's third significant digit, never a fixed decimal count."""

import pytest

from trackproc.pipeline.numbers import format_number, value_sigma


@pytest.mark.parametrize("value, sigma, unit, text", [
    (5e-6, 2.208e-7, "m/s^2", "5.000e-06 ± 2.208e-07  m/s^2"),     # was 0.000005: one digit
    (3774840.90122, 0.18168603306639575, "m", "3774840.901 ± 0.1817     m"),
    (-4816.59986544999, 0.00016777, "m/s", "-4816.599865 ± 0.0001678  m/s"),
    (119.955, 0.36, "m", "119.955 ± 0.36       m"),
])
def test_value_sigma(value, sigma, unit, text):
    assert value_sigma(value, sigma, unit) == text


def test_value_keeps_the_digits_its_sigma_resolves():
    for value, sigma in ((1.234567e-9, 3e-13), (6.02e23, 1e20), (0.5, 0.5)):
        shown = float(value_sigma(value, sigma).split(" ± ")[0])
        assert abs(shown - value) <= sigma / 100          # rounded at most a hundredth of a sigma away


def test_format_number():
    assert format_number(0.18168603306639575) == "0.181686"
    assert format_number(2200000171.425621) == "2200000171.43"
    assert format_number(float("nan")) == "-" and format_number(0.0) == "0"
