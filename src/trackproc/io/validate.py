"""Plausibility checks where inputs enter: re-exported from :mod:`trackproc.types.checks`, their one home
(below ``io``, so the data types of :mod:`trackproc.types` check themselves)."""

from trackproc.types.checks import (  # noqa: F401
    CARRIER_RANGE_HZ, DEFAULT_MAX_INPUT_ROWS, FIRST_YEAR, LAST_YEAR, MAX_LOS_SPEED_M_S, MAX_NAME, MAX_ROWS,
    MAX_SPAN_S, MIN_SPEED_FRACTION, ORBIT_RADIUS_RANGE_M, STATION_HEIGHT_RANGE_M, check_carrier,
    check_distinct_files, check_input_rows, check_iso_year, check_los_speed, check_name, check_no_repeated_samples,
    check_orbit_state, check_rows, check_span, check_station, check_year, doppler_speed_factor, max_input_rows, parse_duration, stated_carrier)
