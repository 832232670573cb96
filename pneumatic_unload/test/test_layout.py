# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Package layout: manifests, the ROS-free core guard, and a real colcon build + ament lookup."""

import ast
import configparser
import contextlib
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

PKG = "pneumatic_unload"
MSGS_PKG = "pneumatic_unload_msgs"
NODES_PKG = f"{PKG}.nodes"
EXECUTABLES = ("estimator", "simulator", "recorder", "replay", "opcua")
# Top-level modules the ROS-free core must never import.
ROS_MODULES = frozenset(
    {
        "rclpy",
        "sensor_msgs",
        "std_msgs",
        MSGS_PKG,
        "diagnostic_msgs",
        "std_srvs",
        "builtin_interfaces",
        "rosidl_runtime_py",
    }
)
COLCON_TIMEOUT_S = 240


# ---------------------------------------------------------------------------- manifests


def _manifest(path: Path) -> ET.Element:
    root = ET.parse(path).getroot()
    assert root.tag == "package", path
    assert root.get("format") == "3", path
    return root


def test_package_xml(repo_root):
    root = _manifest(repo_root / "package.xml")
    assert root.findtext("name") == PKG
    assert root.findtext("export/build_type") == "ament_python"


def test_msg_defs_package_xml(repo_root):
    # the interface package beside this one (colcon and rosdep find both: neither is
    # inside the other's folder)
    assert not (repo_root / "msg_defs").exists()
    root = _manifest(repo_root.parent / MSGS_PKG / "package.xml")
    assert root.findtext("name") == MSGS_PKG
    assert root.findtext("export/build_type") == "ament_cmake"
    groups = [e.text for e in root.findall("member_of_group")]
    assert "rosidl_interface_packages" in groups


def test_setup_cfg_scripts_go_to_lib_pkg(repo_root):
    cfg = configparser.ConfigParser(interpolation=None)
    cfg.read(repo_root / "setup.cfg", encoding="utf-8")
    assert cfg.get("develop", "script_dir") == f"$base/lib/{PKG}"
    assert cfg.get("install", "install_scripts") == f"$base/lib/{PKG}"


def test_ament_resource_marker(repo_root):
    assert (repo_root / "resource" / PKG).is_file()


# ---------------------------------------------------------------- ROS-free core guard


def _core_files(pkg_dir: Path) -> list[Path]:
    """Every .py of the package except those under <pkg>/nodes/."""
    return sorted(p for p in pkg_dir.rglob("*.py") if p.relative_to(pkg_dir).parts[0] != "nodes")


def _imported_names(tree: ast.AST, package: list[str]) -> list[tuple[int, str]]:
    """(line, dotted module name) for every import in tree; package = the module's package."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the module's own package
                base = package[: len(package) - (node.level - 1)]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            found.append((node.lineno, module))
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
        elif isinstance(node, ast.Call) and node.args:  # importlib.import_module("x")
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            arg = node.args[0]
            if fname in ("import_module", "__import__") and isinstance(arg, ast.Constant):
                if isinstance(arg.value, str):
                    found.append((node.lineno, arg.value))
    return found


def _forbidden_imports(pkg_dir: Path) -> list[str]:
    """'file:line: module' for each core import of rclpy, a ROS message package or nodes."""
    bad = []
    for path in _core_files(pkg_dir):
        rel = path.relative_to(pkg_dir.parent).with_suffix("").parts
        package = list(rel[:-1])  # a module's package; for __init__.py, the package itself
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for line, name in _imported_names(tree, package):
            top = name.split(".")[0]
            if top in ROS_MODULES or name == NODES_PKG or name.startswith(NODES_PKG + "."):
                bad.append(f"{path.relative_to(pkg_dir.parent)}:{line}: {name}")
    return bad


# Walks the package with pkgutil.iter_modules (what walk_packages does) but never imports
# <pkg>.nodes: walk_packages imports every subpackage it recurses into, nodes included.
_IMPORT_CORE = textwrap.dedent(
    """
    import importlib, json, pkgutil, sys, traceback
    root, pkg, skip, ros = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split(",")
    sys.path.insert(0, root)
    top = importlib.import_module(pkg)
    imported, errors = [pkg], {}

    def walk(path, prefix):
        for info in pkgutil.iter_modules(path, prefix):
            if info.name == skip:
                continue
            try:
                mod = importlib.import_module(info.name)
            except Exception:
                errors[info.name] = traceback.format_exc(limit=3)
                continue
            imported.append(info.name)
            if info.ispkg:
                walk(mod.__path__, info.name + ".")

    walk(top.__path__, pkg + ".")
    print(json.dumps({"file": top.__file__, "imported": imported, "errors": errors,
                      "ros_loaded": sorted(m for m in ros if m in sys.modules)}))
    """
)


def _import_core_in_subprocess(root: Path) -> dict:
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")  # leave no __pycache__ behind
    proc = subprocess.run(
        [sys.executable, "-c", _IMPORT_CORE, str(root), PKG, NODES_PKG, ",".join(ROS_MODULES)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=root,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert Path(result["file"]).resolve().is_relative_to(root.resolve()), result["file"]
    return result


def test_core_never_imports_ros_statically(repo_root):
    assert _core_files(repo_root / PKG), "no core module found"
    assert _forbidden_imports(repo_root / PKG) == []


def test_core_never_imports_ros_at_runtime(repo_root):
    result = _import_core_in_subprocess(repo_root)
    assert result["errors"] == {}, "\n".join(result["errors"].values())
    assert NODES_PKG not in result["imported"]
    assert result["ros_loaded"] == [], f"core imports pulled in {result['ros_loaded']}"


def test_core_guard_catches_an_rclpy_import(repo_root, tmp_path):
    """The two guards above fail when a core module imports rclpy (checked on a tmp copy)."""
    copy = tmp_path / "src"
    shutil.copytree(repo_root / PKG, copy / PKG, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / PKG / "_scratch_guard.py").write_text("import rclpy  # noqa: F401\n")
    assert _forbidden_imports(copy / PKG) == [f"{PKG}/_scratch_guard.py:1: rclpy"]
    result = _import_core_in_subprocess(copy)
    assert f"{PKG}._scratch_guard" in result["imported"]
    assert "rclpy" in result["ros_loaded"]


@pytest.mark.parametrize(
    ("relpath", "source"),
    [
        ("a.py", "from sensor_msgs.msg import FluidPressure\n"),
        ("a.py", "import rclpy.node as rn\n"),
        ("a.py", "from . import nodes\n"),
        ("sub/__init__.py", "from ..nodes.estimator import main\n"),
        ("a.py", "from pneumatic_unload import nodes\n"),
        ("a.py", "def f():\n    import std_srvs.srv\n"),
        ("a.py", "import importlib\nimportlib.import_module('pneumatic_unload_msgs.msg')\n"),
    ],
)
def test_static_guard_variants(tmp_path, relpath, source):
    pkg_dir = tmp_path / PKG
    (pkg_dir / "nodes").mkdir(parents=True)
    (pkg_dir / "__init__.py").write_text("")
    (pkg_dir / "nodes" / "__init__.py").write_text("import rclpy\n")  # allowed in nodes/
    (pkg_dir / relpath).parent.mkdir(parents=True, exist_ok=True)
    (pkg_dir / relpath).write_text(source)
    bad = _forbidden_imports(pkg_dir)
    assert len(bad) >= 1 and all(b.startswith(f"{PKG}/{relpath}:") for b in bad), bad


# --------------------------------------------------- colcon build + `ros2 run` lookup


def _source_tree_artifacts(src: Path) -> set[str]:
    """Build products colcon could leave in the packages' source folders."""
    found = set()
    for pkg in (src / PKG, src / MSGS_PKG):
        for child in pkg.iterdir():
            if child.name.endswith(".egg-info") or child.name in ("install", "log", "build"):
                found.add(str(child))
    return found


def _clean_copy(repo_root: Path, src: Path) -> None:
    """The repository's two packages as a user's clone has them under a workspace's src/:
    the files git tracks (committed or not), none of the build products."""
    top = repo_root.parent
    listed = subprocess.run(["git", "-C", str(top), "ls-files", "-co", "--exclude-standard",
                             PKG, MSGS_PKG], capture_output=True, text=True, check=True)
    for rel in listed.stdout.splitlines():
        if not (top / rel).is_file():
            continue  # deleted, not yet committed
        dest = src / "repo" / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(top / rel, dest)


def _run_group(cmd: list[str], timeout: float, **kwargs) -> subprocess.CompletedProcess:
    """subprocess.run in its own process group, the whole group killed on timeout."""
    with subprocess.Popen(cmd, start_new_session=True, text=True, **kwargs) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


_LOOKUP = textwrap.dedent(
    """
    import json, os
    from ament_index_python.packages import get_package_prefix
    import pneumatic_unload_msgs.msg as m
    m.UnloadEstimate(conductance=1.0)
    print(json.dumps({"pkg": get_package_prefix("pneumatic_unload"),
                      "msgs": get_package_prefix("pneumatic_unload_msgs"),
                      "msgs_module": m.__file__,
                      "ament_prefix_path": os.environ["AMENT_PREFIX_PATH"]}))
    """
)


def test_colcon_build_and_ros2_run_lookup(repo_root, venv_python, tmp_path):
    """A workspace laid from a clean copy (src/repo/ holding both packages): colcon list
    finds both with no --paths, colcon build builds them, and each installed executable
    starts (``--help``, exit 0) and the simulator comes up over DDS; the CLI is on PATH."""
    prefix = Path(sys.prefix)
    colcon = prefix / "bin" / "colcon"
    assert colcon.is_file(), f"{colcon} missing: run scripts/setup_venv.sh"
    src = tmp_path / "src"
    _clean_copy(repo_root, src)
    repo_root = src / "repo"
    build, install, log = tmp_path / "build", tmp_path / "install", tmp_path / "log"
    env = dict(
        os.environ,
        CMAKE_PREFIX_PATH=str(prefix),
        AMENT_PREFIX_PATH=str(prefix),
        PATH=f"{prefix / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
        COLCON_HOME=str(tmp_path / "colcon_home"),  # no user defaults.yaml / mixins
    )
    env.pop("COLCON_DEFAULTS_FILE", None)
    listed = _run_group([str(colcon), "--log-base", str(log), "list", "--base-paths",
                         str(src)], 60, cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                        stderr=subprocess.STDOUT)
    assert listed.returncode == 0, listed.stdout
    names = {line.split("\t")[0] for line in listed.stdout.splitlines() if "\t" in line}
    assert names == {PKG, MSGS_PKG}, listed.stdout
    cmd = [
        str(colcon), "--log-base", str(log), "build", "--base-paths", str(src),
        "--build-base", str(build), "--install-base", str(install),
        "--cmake-args", "-DBUILD_TESTING=OFF", f"-DPython3_EXECUTABLE={venv_python}",
    ]  # fmt: skip
    before = _source_tree_artifacts(repo_root)
    proc = _run_group(
        cmd, COLCON_TIMEOUT_S, cwd=tmp_path, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-6000:]
    assert _source_tree_artifacts(repo_root) - before == set(), "colcon wrote into the sources"
    assert (install / ".colcon_install_layout").read_text().strip() == "isolated"

    # What a user does: source the install's local_setup, then `ros2 run` = ament index
    # lookup of the package prefix + exec <prefix>/lib/<pkg>/<exe>.
    lookup_env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix))
    proc = subprocess.run(
        ["bash", "-c", 'source "$1/local_setup.bash" && exec "$2" -c "$3"', "lookup",
         str(install), str(venv_python), _LOOKUP],
        cwd=tmp_path, env=lookup_env, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    pkg_prefix, msgs_prefix = Path(found["pkg"]), Path(found["msgs"])
    assert pkg_prefix == install / PKG
    assert msgs_prefix == install / MSGS_PKG
    assert Path(found["msgs_module"]).is_relative_to(msgs_prefix)
    paths = found["ament_prefix_path"].split(os.pathsep)
    assert {str(pkg_prefix), str(msgs_prefix)} <= set(paths[:2]) and paths[-1] == str(prefix)

    for exe in EXECUTABLES:
        script = pkg_prefix / "lib" / PKG / exe
        assert script.is_file(), f"{script} missing"
        assert os.access(script, os.X_OK), f"{script} not executable"
        shebang = script.read_text().splitlines()[0]
        assert shebang.startswith("#!") and Path(shebang[2:].split()[0]).parent == prefix / "bin"
    assert (pkg_prefix / "share" / PKG / "package.xml").is_file()
    for yaml_name in ("simulator.yaml", "estimator.yaml", "recorder.yaml", "replay.yaml",
                      "opcua.yaml"):
        assert (pkg_prefix / "share" / PKG / "config" / yaml_name).is_file()
    assert (msgs_prefix / "share" / MSGS_PKG / "msg" / "UnloadEstimate.msg").is_file()
    assert (pkg_prefix / "share" / PKG / "foxglove" / "pneumatic_unload.json").is_file()
    assert list((pkg_prefix / "share" / PKG / "bags").glob("*/metadata.yaml"))

    # each executable starts from the install (ros2 run's exec), the CLI from PATH
    # (python3 on PATH is the one with the dependencies, as rosdep makes the system's)
    run_env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix),
                   ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", "0"),
                   PATH=f"{prefix / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    run_env.pop("PYTHONPATH", None)

    def sourced(command: str, timeout: float = 120) -> subprocess.CompletedProcess:
        return subprocess.run(["bash", "-c", f'source "$1/local_setup.bash" && {command}',
                               "run", str(install)], cwd=tmp_path, env=run_env,
                              capture_output=True, text=True, timeout=timeout, check=False)

    for exe in EXECUTABLES:
        proc = sourced(f'"{pkg_prefix / "lib" / PKG / exe}" --help')
        assert proc.returncode == 0 and "--ros-args" in proc.stdout + proc.stderr, (
            exe, proc.stdout[-1500:], proc.stderr[-1500:])
    proc = sourced("command -v pneumatic-unload && pneumatic-unload --help")
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert proc.stdout.splitlines()[0] == str(pkg_prefix / "bin" / "pneumatic-unload")
    # the simulator comes up over DDS (its start line), stopped by SIGINT once it is up
    sim = subprocess.Popen(
        ["bash", "-c", 'source "$1/local_setup.bash" && exec "$2"', "run", str(install),
         str(pkg_prefix / "lib" / PKG / "simulator")],
        cwd=tmp_path, env=run_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        start_new_session=True)
    seen, deadline = b"", time.monotonic() + 120.0
    try:
        assert sim.stdout is not None
        fd = sim.stdout.fileno()
        while b"rig at" not in seen and time.monotonic() < deadline:
            ready, _, _ = select.select([fd], [], [], 1.0)
            chunk = os.read(fd, 4096) if ready else b""
            if ready and not chunk:
                break  # it exited
            seen += chunk
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(sim.pid, signal.SIGINT)
        rest, _ = sim.communicate(timeout=60)
    assert b"rig at" in seen, (seen + rest)[-2000:]
    assert sim.returncode == 0, (sim.returncode, (seen + rest)[-2000:])


# ------------------------------------------------------------- layers, cycles and sizes
#: Layer of each top-level part of the core (lower layers never import higher ones; a part
#: may import its own layer). Read top to bottom as the architecture.
LAYERS: dict[str, int] = {
    "physics": 0,  # the flow law and the paper's closed forms (eq 38-40, the isentropic C)
    "charge": 0,  # the charge test's closed forms (the method mirrored, its bias)
    "real_gas": 0,  # second virial coefficients: where the ideal gas departs from the real
    "config": 1,  # settings declared once: units, ranges, meanings
    "io": 2,  # bags and CSV files: data, no physics
    "fit": 2,  # the fitting engine: parameters, likelihood, least squares, uncertainty
    "selection": 2,  # the one rule among candidate models: criterion, weights, model average
    "model": 3,  # the discharge model (ODE, heat law, sensor, effects), its stream, its inversion
    "uncertainty": 4,  # the uncertainty budget of C and b (GUM: type A, type B, model form)
    "curvefit": 5,  # model-based C and b: the final curve fit, its budget lines; the SSE fit
    "estimation": 6,  # the streaming estimator and batch analysis
    "discrepancy": 7,  # where model and measurement disagree: the missing effect named
    "analysis": 7,  # the offline analysis: records in, text, JSON and plots out; simulated runs
    "testline": 7,  # batch on Dask, the results database, part specifications
    "app": 8,  # the command line, the demo, the process launcher
    "plc": 8,  # the OPC UA server of the cell's PLC (asyncua; the opcua node's core)
    "nodes": 9,  # the ROS 2 nodes (thin: parameters, messages, core calls)
}
#: Largest core module [lines] ("about 500").
MAX_CORE_LINES = 520


def _module_name(path: Path, pkg_dir: Path) -> str:
    parts = list(path.relative_to(pkg_dir.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _runtime_imports(tree: ast.AST, package: list[str]) -> list[tuple[int, str, list[str]]]:
    """(line, module, names) of every import outside ``if TYPE_CHECKING:`` blocks."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                skip.update(id(n) for n in ast.walk(sub))
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            out.append((node.lineno, module, [a.name for a in node.names]))
    return out


def _import_graph(pkg_dir: Path) -> tuple[dict[str, set[str]], list[str]]:
    """Module -> package modules it imports (runtime), and private-name imports found."""
    files = {_module_name(p, pkg_dir): p for p in pkg_dir.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in files}
    private = []
    for mod, path in files.items():
        package = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for line, target, names in _runtime_imports(tree, package):
            if not target.startswith(PKG):
                continue
            for name in names or [""]:
                full = f"{target}.{name}" if name else target
                dest = full if full in files else target
                if dest in files and dest != mod:
                    graph[mod].add(dest)
                if name.startswith("_") and not name.startswith("__") and target != mod:
                    private.append(f"{path.relative_to(pkg_dir.parent)}:{line}: "
                                   f"from {target} import {name}")
    return graph, private


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def _part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_no_import_cycles(repo_root):
    graph, _ = _import_graph(repo_root / PKG)
    # a package's __init__ re-exporting its own modules is not a cycle of roles
    graph = {m: {d for d in ds if not (m.startswith(d + ".") or d.startswith(m + "."))}
             for m, ds in graph.items()}
    assert _cycles(graph) == []


def test_no_private_name_is_imported_across_modules(repo_root):
    _, private = _import_graph(repo_root / PKG)
    assert private == []


def test_layers_only_point_down(repo_root):
    graph, _ = _import_graph(repo_root / PKG)
    parts = {_part(m) for m in graph} - {""}
    assert parts <= set(LAYERS), f"give each new part a layer: {parts - set(LAYERS)}"
    bad = [f"{m} -> {d}" for m, ds in graph.items() for d in ds
           if _part(m) and _part(d) and LAYERS[_part(d)] > LAYERS[_part(m)]]
    assert bad == []


def _code_lines(path: Path) -> int:
    """Lines of a module without its licence header (the SPDX and copyright comments)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    header = 0
    while header < len(lines) and lines[header].startswith("#") \
            and ("SPDX-License-Identifier" in lines[header] or "Copyright" in lines[header]):
        header += 1
    return len(lines) - header


def test_core_modules_are_small(repo_root):
    pkg_dir = repo_root / PKG
    big = {str(p.relative_to(repo_root)): n for p in _core_files(pkg_dir)
           if (n := _code_lines(p)) > MAX_CORE_LINES}
    assert big == {}


#: what makes a test module run alone after the parallel part of ``make test``
#: (conftest.py): node processes in real time over DDS, servers on ports, a Dask
#: cluster's processes, kill -9 timings (a headless browser, which only renders a file
#: within a generous timeout, runs with the rest)
SERIAL_SIGNS = ("NodeProcess", "ros_node", "rclpy", "asyncua", "pg_url", "LocalCluster",
                "SIGKILL")


def test_modules_with_nodes_servers_or_timings_run_alone(repo_root):
    missing = []
    for path in sorted((repo_root / "test").glob("test_*.py")):
        text = path.read_text()
        signs = [s for s in SERIAL_SIGNS if s in text]
        if signs and "pytest.mark.serial" not in text:
            missing.append(f"{path.name} ({', '.join(signs)})")
    assert missing == [], ("mark these modules pytestmark = pytest.mark.serial: "
                           + "; ".join(missing))
