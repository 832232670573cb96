# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The real measurements in ``../shared/real-data`` (read in place, never copied).

A clone without ``../shared/real-data`` skips the real-data tests; with it present, a file
that is missing fails them (a renamed or lost file must not turn a test into a skip).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path
from typing import Any

import pytest

#: ``shared/real-data`` beside the checkout.
REAL_DATA = Path(__file__).resolve().parents[3] / "shared" / "real-data"


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


#: How the AeroLab runs are read: the rig's tank [m^3], gauge kPa, the lab's p_atm [Pa].
AEROLAB_ARGS = ("--volume", "0.125", "--gauge", "--atmosphere", "101500", "--pressure-unit",
                "kPa")
#: The runs that begin after their valve opening, with the first stamp [s] given as the
#: opening: the 0.094 in run falls at its first row at 90 % of its initial rate (no opening
#: ramp; the 0.125 in run shows its ramp), so without ``--start-time`` its unload is refused
#: (its start and p10 are not in the record).
AEROLAB_START = {"orifice_0.094in.csv": "28"}


def aerolab_args(name: str) -> tuple[str, ...]:
    """:data:`AEROLAB_ARGS` for the run ``name``, with its ``--start-time`` where it
    begins after the opening (:data:`AEROLAB_START`)."""
    start = AEROLAB_START.get(name)
    return AEROLAB_ARGS if start is None else (*AEROLAB_ARGS, "--start-time", start)


#: ``analyze --json``'s output per AeroLab run, made once for the session's tests (each
#: asserts another property of one deterministic analysis; 5-10 s a run) [name -> text].
_AEROLAB_JSON: dict[str, str] = {}


def aerolab_json(name: str) -> dict[str, Any]:
    """``pneumatic-unload analyze --json`` (with :func:`aerolab_args`) of the AeroLab run
    ``name`` (e.g. 'orifice_0.094in.csv'), parsed; the CLI runs in-process once per run."""
    from pneumatic_unload.app.cli import main

    if name not in _AEROLAB_JSON:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = main(["analyze", str(real_file(f"aerolab/{name}")),
                         *aerolab_args(name), "--json"])
        assert code == 0, f"analyze {name} exited {code}"
        _AEROLAB_JSON[name] = out.getvalue()
    return json.loads(_AEROLAB_JSON[name])
