# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``make setup`` (scripts/setup_venv.sh) says what it does while pip installs the pinned
set: a first run took 15 minutes with no line shown (pip ran with -q)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

#: A stand-in for the venv's python: ``-m pip install`` prints what pip prints (or fails
#: with FAIL set; with GATE set it waits after its first package until that file exists),
#: anything else stops the script after the pip step (exit 3).
FAKE_PYTHON = """#!/bin/bash
if [ "$1 $2 $3" = "-m pip install" ]; then
  echo "WARNING: Location '/x' is ignored: it is neither a file nor a directory."
  echo "Collecting click==8.5.1 (from -r requirements.lock (line 2))"
  echo "  Downloading click-8.5.1-py3-none-any.whl (98 kB)"
  if [ -n "$GATE" ]; then while [ ! -e "$GATE" ]; do sleep 0.1; done; fi
  echo "Collecting numpy==2.0.2 (from -r requirements.lock (line 3))"
  [ -n "$FAIL" ] && { echo "ERROR: No matching distribution found for numpy==2.0.2"; exit 1; }
  echo "Installing collected packages: click, numpy"
  echo "Successfully installed click-8.5.1 numpy-2.0.2"
  exit 0
fi
exit 3
"""


def _prepare(tmp: Path) -> None:
    (tmp / "scripts").mkdir(exist_ok=True)
    shutil.copy(REPO / "scripts" / "setup_venv.sh", tmp / "scripts")
    (tmp / "requirements.lock").write_text("# pinned\nclick==8.5.1\nnumpy==2.0.2\n")
    venv = tmp / ".venv"
    (venv / "bin").mkdir(parents=True, exist_ok=True)
    py = venv / "bin" / "python"
    py.write_text(FAKE_PYTHON)
    py.chmod(0o755)
    (venv / ".requirements.lock").unlink(missing_ok=True)


def _run(tmp: Path, fail: bool) -> subprocess.CompletedProcess[str]:
    _prepare(tmp)
    env = {**os.environ, "FAIL": "1" if fail else "", "GATE": ""}
    return subprocess.run(["bash", "scripts/setup_venv.sh"], cwd=tmp, env=env,
                          capture_output=True, text=True, timeout=60)


def test_setup_lists_each_package_and_says_how_long_it_may_take(tmp_path: Path):
    r = _run(tmp_path, fail=False)
    out = r.stdout
    assert "2 packages" in out and "min" in out, out  # what it does, roughly how long
    assert "[setup]   1/2 click==8.5.1" in out and "[setup]   2/2 numpy==2.0.2" in out, out
    assert "unpacking the packages" in out and "done: 2 package(s) installed" in out, out
    assert "is ignored" not in out  # the pip config's noise stays out
    assert "Downloading" in (tmp_path / ".venv" / "pip-install.log").read_text()


def test_a_failing_pip_says_so_and_where_its_output_is(tmp_path: Path):
    r = _run(tmp_path, fail=True)
    assert r.returncode == 1, (r.returncode, r.stdout, r.stderr)
    assert "ERROR: No matching distribution found for numpy==2.0.2" in r.stdout
    assert "pip failed; its whole output: .venv/pip-install.log" in r.stderr
    assert not (tmp_path / ".venv" / ".requirements.lock").exists()  # tried again next time


def test_each_package_is_shown_while_pip_still_runs(tmp_path: Path):
    """The first package's line arrives while pip is still busy (no filter that buffers
    pip's output until it ends, as mawk does with its input)."""
    import select

    _prepare(tmp_path)
    gate = tmp_path / "gate"
    proc = subprocess.Popen(["bash", "scripts/setup_venv.sh"], cwd=tmp_path,
                            env={**os.environ, "FAIL": "", "GATE": str(gate)},
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    # the pipe is read with os.read, not through a buffered file object: its buffer may
    # hold the awaited line already read while select() waits on the empty descriptor
    seen = b""
    try:
        assert proc.stdout is not None
        fd = proc.stdout.fileno()
        while b"1/2 click" not in seen:
            ready, _, _ = select.select([fd], [], [], 30.0)
            assert ready, f"no progress line while pip runs: {seen!r}"
            chunk = os.read(fd, 4096)
            assert chunk, f"the script ended before its first package line: {seen!r}"
            seen += chunk
    finally:
        gate.touch()
        proc.communicate(timeout=60)
