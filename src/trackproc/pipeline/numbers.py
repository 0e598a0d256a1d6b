"""Numbers as people read them in summaries: significant digits, not a fixed count of decimals
(a fixed ``.6f`` prints 5e-6 m/s^2 as ``0.000005`` and hides a 1e-9 value as ``0.000000``)."""

from __future__ import annotations

import math


def format_number(value: float, digits: int = 7) -> str:
    """``digits`` significant digits (12 from 1e5 up, so that metres of an orbit keep their
    millimetres and hertz of a carrier their hundredths); ``-`` for NaN/inf."""
    if value is None or not math.isfinite(value):
        return "-"
    if value == 0:
        return "0"
    return f"{value:.{digits if abs(value) < 1e5 else 12}g}"


def value_sigma(value: float, sigma: float, unit: str = "", width: int = 0) -> str:
    """``value ± sigma unit`` with the value to the sigma's third significant digit and the sigma
    to four: ``5.012e-06 ± 2.208e-07 m/s^2``, ``3774840.901 ± 0.1817 m``; the value right-aligned
    in ``width`` characters (a column of them lines up on the ``±``)."""
    if not (math.isfinite(value) and math.isfinite(sigma)) or sigma <= 0:
        left, right = format_number(value), format_number(sigma, 4)
    else:
        magnitude = math.floor(math.log10(abs(value))) if value else math.floor(math.log10(sigma))
        digits = min(17, max(3, magnitude - math.floor(math.log10(sigma)) + 3))
        left, right = f"{value:#.{digits}g}".rstrip("."), f"{sigma:.4g}"   # '#': 5.000e-06 keeps its digits
    return f"{left:>{width}} ± {right:<10} {unit}".rstrip()
