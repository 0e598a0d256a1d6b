"""The line-of-sight speed check of range-rate and Doppler inputs (``io.validate.check_los_speed``):
the Doppler bound is 12 km/s times ``k f / c`` (eq. 4: k = 1 one-way, 2 two-way), computed here
from the speed of light and the carrier, and a carrier given in the wrong unit is caught."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc.errors import InputError
from trackproc.io.validate import check_los_speed

C = 299_792_458.0          # m/s, exact (SI definition)
LEO_M_S = 7000.0


@pytest.mark.parametrize("mode, k", [("one-way", 1.0), ("two-way", 2.0)])
def test_doppler_of_a_leo_pass_passes_and_a_carrier_100_times_too_small_is_caught(mode, k):
    carrier = 2.2e9
    doppler = -k * carrier * np.linspace(-LEO_M_S, LEO_M_S, 101) / C          # eq. (4), |f_D| up to 103 kHz two-way
    check_los_speed(doppler, "doppler", carrier_hz=carrier, mode=mode)      # plausible: nothing raised
    with pytest.raises(InputError) as caught:
        check_los_speed(doppler, "doppler", carrier_hz=carrier / 100, mode=mode, file="p.csv", column="doppler_hz")
    # the median |Doppler| then implies 100 x 3.5 km/s; the bound is 12 km/s at the stated carrier
    bound_hz = 12_000.0 * k * (carrier / 100) / C
    assert f"{bound_hz:.6g} Hz" in caught.value.expected and "is the carrier in Hz?" in caught.value.expected
    assert f"{100 * LEO_M_S / 2 / 1000:.4g} km/s" in str(caught.value.detail)


def test_range_rate_beyond_12_km_s_is_caught_and_without_a_carrier_doppler_is_not_checked():
    check_los_speed([11_999.0, -11_999.0], "range_rate")
    with pytest.raises(InputError):
        check_los_speed([0.0, 12_001.0], "range_rate")
    check_los_speed([1e9], "doppler")                                        # no carrier: no bound
