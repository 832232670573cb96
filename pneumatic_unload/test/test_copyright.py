# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""REP-2004 copyright check (ament_python's test_copyright.py): every source file of both
packages states its licence (SPDX identifier, as package.xml declares) and a copyright line.

ament_copyright has no wheel on PyPI, so this test does its check: the headers of the
Python, C, interface (.msg/.action), CMake and installed script files.
"""

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

#: the repository root (both package folders side by side)
ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("pneumatic_unload", "pneumatic_unload_msgs")
#: how far into a file the header must be [characters] (after a shebang line)
HEADER_SPAN = 400
SKIP_DIRS = {"build", "install", "log", "__pycache__", ".venv", "runs"}
COPYRIGHT = re.compile(r"Copyright \d{4}(-\d{4})? \S")


def _sources() -> list[Path]:
    found: list[Path] = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*")):
            if not path.is_file() or SKIP_DIRS & set(path.relative_to(ROOT).parts):
                continue
            if path.suffix in (".py", ".c", ".h", ".msg", ".action", ".srv") \
                    or path.name == "CMakeLists.txt" or path.parent.name == "bin":
                found.append(path)
    return found


def _licence(pkg: str) -> str:
    node = ET.parse(ROOT / pkg / "package.xml").getroot().find("license")
    assert node is not None and node.text, f"{pkg}/package.xml declares no licence"
    return node.text.strip()


def test_both_packages_declare_apache_2():
    assert [_licence(p) for p in PACKAGES] == ["Apache-2.0", "Apache-2.0"]
    assert "Apache License" in (ROOT / "pneumatic_unload" / "LICENSE").read_text()


def test_the_scan_sees_every_kind_of_source():
    kinds = {p.name if p.name == "CMakeLists.txt" else p.suffix for p in _sources()}
    assert {".py", ".c", ".msg", ".action", "CMakeLists.txt"} <= kinds
    assert len(_sources()) > 200


@pytest.mark.parametrize("pkg", PACKAGES)
def test_every_source_file_has_an_spdx_and_copyright_header(pkg):
    spdx = f"SPDX-License-Identifier: {_licence(pkg)}"
    bad = []
    for path in _sources():
        if path.relative_to(ROOT).parts[0] != pkg:
            continue
        head = path.read_text(encoding="utf-8", errors="replace")[:HEADER_SPAN]
        if spdx not in head or not COPYRIGHT.search(head):
            bad.append(str(path.relative_to(ROOT)))
    assert not bad, f"no '{spdx}' + 'Copyright YEAR HOLDER' header in: {bad}"
