"""The real measurements in ``../shared/real-data`` (read in place, never copied).

A clone without ``../shared/real-data`` skips the real-data tests; with it present, a file
that is missing fails them (a renamed or lost file must not turn a test into a skip).
"""

from __future__ import annotations

from pathlib import Path

import pytest

#: ``shared/real-data`` beside the checkout.
REAL_DATA = Path(__file__).resolve().parents[2] / "shared" / "real-data"


def real_file(relative: str) -> Path:
    """The path of a real-data file (relative to :data:`REAL_DATA`); skips the test when
    the real data are not beside this checkout, fails it when they are but the file is
    not."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"no real data beside this checkout ({REAL_DATA})")
    path = REAL_DATA / relative
    if not path.is_file():
        pytest.fail(f"real-data file missing: {path} (the folder {REAL_DATA} is present)")
    return path
