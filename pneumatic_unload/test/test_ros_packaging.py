# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The package as a ROS 2 user gets it: package.xml declares by its rosdep key every
third-party module the package imports at module level, modules without a key stay
optional, the files a colcon build installs, the executor guard for old rclpy, and the
tests install no system package unless asked."""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

#: run alone, after the parallel part of make test (an rclpy context; see conftest.py)
pytestmark = pytest.mark.serial

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIR = ROOT / "pneumatic_unload"

#: The rosdep key (rosdistro's rosdep/base.yaml, rosdep/python.yaml; ROS packages by
#: name) of each third-party module the package imports.
ROSDEP_KEYS = {
    "numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib", "sqlalchemy": "python3-sqlalchemy",
    "alembic": "python3-alembic", "psutil": "python3-psutil", "tqdm": "python3-tqdm",
    "rosbags": "python3-rosbags-pip", "mcap": "mcap-ros2-support",
    "rclpy": "rclpy", "rcl_interfaces": "rcl_interfaces", "std_msgs": "std_msgs",
    "sensor_msgs": "sensor_msgs", "std_srvs": "std_srvs", "diagnostic_msgs": "diagnostic_msgs",
    "builtin_interfaces": "builtin_interfaces", "pneumatic_unload_msgs": "pneumatic_unload_msgs",
    "rosgraph_msgs": "rosgraph_msgs",
}
#: Modules with no rosdep key: optional, imported only inside the functions (or the
#: OPC UA bridge's own modules) that use them.
OPTIONAL = {"asyncua": ("pneumatic_unload/plc/", "pneumatic_unload/nodes/opcua.py"),
            # asyncua's own dependency (installed with it), used by the bridge's TLS checks
            "cryptography": ("pneumatic_unload/plc/",),
            "dask": (), "distributed": (), "pyarrow": (), "lz4": (), "zstandard": (),
            "psycopg": ()}


def _imports(tree: ast.Module) -> list[tuple[str, bool]]:
    """(top-level module, imported at module level) of every absolute import."""
    out: list[tuple[str, bool]] = []

    def walk(body: list[ast.stmt], top: bool) -> None:
        for n in body:
            if isinstance(n, ast.Import):
                out.extend((a.name.split(".")[0], top) for a in n.names)
            elif isinstance(n, ast.ImportFrom) and n.level == 0 and n.module:
                out.append((n.module.split(".")[0], top))
            elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                walk(n.body, False)
            elif isinstance(n, ast.ClassDef):
                walk(n.body, top)
            elif isinstance(n, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
                for field in ("body", "orelse", "finalbody"):
                    walk(getattr(n, field, None) or [], top)
                for h in getattr(n, "handlers", []):
                    walk(h.body, top)
    walk(tree.body, True)
    return out


def _scan() -> dict[str, dict[str, bool]]:
    """module -> {file: imported at module level there} of the third-party imports."""
    found: dict[str, dict[str, bool]] = {}
    for f in sorted(PACKAGE_DIR.rglob("*.py")):
        rel = f.relative_to(ROOT).as_posix()
        for mod, top in _imports(ast.parse(f.read_text(encoding="utf-8"))):
            if mod in sys.stdlib_module_names or mod in ("pneumatic_unload", "__future__"):
                continue
            seen = found.setdefault(mod, {})
            seen[rel] = seen.get(rel, False) or top
    return found


def _declared() -> dict[str, set[str]]:
    root = ET.parse(ROOT / "package.xml").getroot()
    kinds: dict[str, set[str]] = {}
    for el in root:
        if el.tag.endswith("depend"):
            kinds.setdefault(el.tag, set()).add((el.text or "").strip())
    return kinds


def test_every_third_party_import_is_declared_by_its_rosdep_key() -> None:
    declared = _declared()
    run = declared.get("exec_depend", set()) | declared.get("depend", set())
    found = _scan()
    unknown = sorted(set(found) - set(ROSDEP_KEYS) - set(OPTIONAL))
    assert not unknown, f"imports with no rosdep key listed here: {unknown}"
    missing = sorted(f"{m} ({ROSDEP_KEYS[m]})" for m in found
                     if m in ROSDEP_KEYS and ROSDEP_KEYS[m] not in run)
    assert not missing, f"package.xml lacks exec_depend of {missing}"
    assert {"python3-pytest", "python3-hypothesis"} <= declared["test_depend"]


def test_a_module_without_a_rosdep_key_is_optional() -> None:
    for mod, files in _scan().items():
        if mod not in OPTIONAL:
            continue
        at_top = [f for f, top in files.items() if top
                  and not any(f.startswith(allowed) for allowed in OPTIONAL[mod])]
        assert not at_top, f"{mod} (no rosdep key) imported at module level in {at_top}"


def test_the_opc_ua_bridge_says_how_to_install_asyncua(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """asyncua has no rosdep key: without it the bridge's import says what to install."""
    for name in [m for m in sys.modules if m == "pneumatic_unload.plc"
                 or m.startswith("pneumatic_unload.plc.") or m.split(".")[0] == "asyncua"]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "asyncua", None)  # import asyncua -> ImportError
    with pytest.raises(ImportError, match=r"pip install asyncua"):
        import pneumatic_unload.plc  # noqa: F401


def test_setup_installs_what_a_ros_user_finds() -> None:
    """colcon build's install: the CLI in bin/ (on PATH once sourced), the reference bags,
    LICENSE and CHANGELOG.rst in share/; colcon test's dependencies in extras_require."""
    import setuptools

    got: dict = {}
    real = setuptools.setup
    try:
        setuptools.setup = lambda **kw: got.update(kw)  # type: ignore[assignment]
        import os

        cwd = os.getcwd()
        os.chdir(ROOT)
        try:
            exec(compile((ROOT / "setup.py").read_text(), "setup.py", "exec"), {})
        finally:
            os.chdir(cwd)
    finally:
        setuptools.setup = real  # type: ignore[assignment]
    files = {dest: srcs for dest, srcs in got["data_files"]}
    assert files["bin"] == ["bin/pneumatic-unload"]
    assert (ROOT / "bin" / "pneumatic-unload").stat().st_mode & 0o111
    bags = {d for d in files if d.startswith("share/pneumatic_unload/bags/")}
    assert {f"share/pneumatic_unload/bags/{p.name}" for p in (ROOT / "bags").iterdir()
            if p.is_dir()} == bags
    assert all(any(s.endswith(".mcap") for s in files[d]) for d in bags)
    assert {"LICENSE", "CHANGELOG.rst"} <= set(files["share/pneumatic_unload"])
    assert {"pytest", "hypothesis"} <= set(got["extras_require"]["test"])


def test_the_license_file_is_the_license_package_xml_names() -> None:
    license_xml = ET.parse(ROOT / "package.xml").getroot().findtext("license")
    assert license_xml == "Apache-2.0"
    text = (ROOT / "LICENSE").read_text()
    assert "Apache License" in text and "Version 2.0, January 2004" in text
    assert (ROOT / "CHANGELOG.rst").read_text().startswith("^^^")


def test_an_rclpy_without_the_events_executor_runs_the_single_threaded_one(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """rclpy before 7.1.4 has no rclpy.experimental: a warning, not an ImportError."""
    import rclpy.executors

    from pneumatic_unload.nodes import common

    monkeypatch.setitem(sys.modules, "rclpy.experimental", None)
    rclpy.init()
    try:
        with pytest.warns(RuntimeWarning, match="no EventsExecutor"):
            ex = common.make_executor("events")
        assert isinstance(ex, rclpy.executors.SingleThreadedExecutor)
        ex.shutdown()
    finally:
        rclpy.try_shutdown()


def test_the_postgres_helper_installs_nothing_unless_asked(monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """test/pgserver.py runs apt-get only with PNEUMATIC_UNLOAD_TEST_INSTALL_POSTGRES=1."""
    import subprocess

    import pgserver

    calls: list = []
    monkeypatch.setattr(subprocess, "run", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(pgserver.os, "geteuid", lambda: 0)
    monkeypatch.delenv(pgserver.INSTALL_ENV, raising=False)
    why = pgserver._install()
    assert calls == [] and pgserver.INSTALL_ENV in why


def test_the_parameter_files_are_keyed_by_any_node_name() -> None:
    import yaml

    for f in sorted((ROOT / "config").glob("*.yaml")):
        assert list(yaml.safe_load(f.read_text())) == ["/**"], f


def test_the_simulator_and_an_analysis_run_with_no_compiler_on_path(tmp_path: Path) -> None:
    """ros-core images carry no C compiler: the kernel and the crossing fit were compiled
    when the package was built (setup.py's extensions), so the simulated rig (the simulator
    node's model) and ``pneumatic-unload analyze`` run with no cc, gcc or CC, and an empty
    kernel cache."""
    import os
    import subprocess

    from pneumatic_unload.estimation import regression
    from pneumatic_unload.model import kernel

    assert kernel.prebuilt() is not None, "the package's build left no compiled kernel"
    assert kernel.prebuilt(Path(regression.__file__).with_name("regression.c")) is not None
    bindir = tmp_path / "bin"  # PATH: an empty folder (the interpreter by its own path)
    bindir.mkdir()
    code = (
        "import json, shutil\n"
        "from pathlib import Path\n"
        "assert shutil.which('cc') is None and shutil.which('gcc') is None\n"
        "from pneumatic_unload.analysis.runs import write_simulated_bag\n"
        "from pneumatic_unload.app.cli import main\n"
        "from pneumatic_unload.config import RigConfig\n"
        f"out = Path({str(tmp_path / 'bag')!r})\n"
        "write_simulated_bag(RigConfig(volume=0.001, conductance=8e-9, rate=200.0), out,"
        " analyze_live=True)\n"
        "raise SystemExit(main(['analyze', str(out), '--json']))\n")
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH")}
    env.update(PATH=str(bindir), PNEUMATIC_UNLOAD_KERNEL_DIR=str(tmp_path / "no-cache"),
               PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True,
                         text=True, env=env, timeout=600)
    assert out.returncode in (0, 1), (out.stdout[-2000:], out.stderr[-3000:])
    import json

    doc = json.loads(out.stdout[out.stdout.index("{"):])  # after the writer's own lines
    final = [u for u in doc["unloads"] if u["final"]]
    assert final and final[0]["conductance_model"] == pytest.approx(8e-9, rel=0.02)
    assert not list((tmp_path / "no-cache").glob("*.so"))
