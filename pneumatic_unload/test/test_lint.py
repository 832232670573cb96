# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""REP-2004 lint check (ament_python's test_flake8.py / test_pep257.py): both packages
pass the project's ruff configuration (ruff.toml: pycodestyle, pyflakes, import order,
bugbear, pyupgrade, annotations).

The project's style is ruff's (100 columns); ament_flake8's ROS
configuration (99 columns; ament_pep257: the pep257 docstring rules) contradicts it, so
``colcon test`` runs this instead (ament_copyright: test_copyright.py).
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _ruff() -> str:
    local = Path(sys.executable).with_name("ruff")
    found = str(local) if local.is_file() else shutil.which("ruff")
    if found is None:
        pytest.skip("ruff is not installed (pip install ruff)")
    return found


def test_ruff_passes_on_both_packages():
    proc = subprocess.run(
        [_ruff(), "check", "--no-cache", "--config", str(ROOT / "ruff.toml"),
         "pneumatic_unload", "pneumatic_unload_msgs"],
        cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_would_catch_an_unused_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import os\n")
    proc = subprocess.run(
        [_ruff(), "check", "--no-cache", "--config", str(ROOT / "ruff.toml"), str(bad)],
        capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "F401" in proc.stdout
