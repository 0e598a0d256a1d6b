"""Where the real tracking data live (../shared/realdata beside the checkout), and the marks
that skip a validation module, with the reason, when they are absent."""

import re
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
REALDATA = SHARED / "realdata"
DOPTRACK = REALDATA / "doptrack-delfic3"
W3B = REALDATA / "orekit-w3b"


def requires(path: Path) -> list:
    """``pytestmark`` of a validation module that reads ``path``."""
    return [pytest.mark.realdata,
            pytest.mark.skipif(not path.is_dir(), reason=f"real data not available: {path} is absent "
                               "(CI checks it out beside the repository)")]


#: The stations table's columns, as W3B's stations give them.
W3B_STATION_COLUMNS = ("station", "lat_deg", "lon_deg", "height_m", "range_bias_m")


def w3b_station_rows() -> list:
    """W3B's stations from the ``ground.station.*  [i] = value`` keys of Orekit's od_test_W3.in, in
    their order: ``[{column: text}]`` with :data:`W3B_STATION_COLUMNS`."""
    keys = {"name": "station", "latitude": "lat_deg", "longitude": "lon_deg", "altitude": "height_m",
            "range.bias": "range_bias_m"}
    rows: dict[int, dict] = {}
    pattern = re.compile(r"^ground\.station\.([a-z.]+)\s*\[(\d+)\]\s*=\s*(\S+)")
    for line in (W3B / "od_test_W3.in").read_text().splitlines():
        match = pattern.match(line.strip())
        if match and match.group(1) in keys:
            rows.setdefault(int(match.group(2)), {})[keys[match.group(1)]] = match.group(3)
    return [r for _, r in sorted(rows.items())]


def w3b_stations_csv(path: Path) -> Path:
    """:func:`w3b_station_rows` as a stations table (CSV) at ``path``."""
    path.write_text(",".join(W3B_STATION_COLUMNS) + "\n"
                    + "\n".join(",".join(r[c] for c in W3B_STATION_COLUMNS) for r in w3b_station_rows()) + "\n")
    return path
