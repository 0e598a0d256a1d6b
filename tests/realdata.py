"""Where the real tracking data live (../shared/realdata beside the checkout), and the marks
that skip a validation module, with the reason, when they are absent."""

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
