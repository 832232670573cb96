# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A minimal process launcher for the nodes (what a ROS 2 launch file does, without ROS).

There is no ``ros2 launch`` on a PyPI-only machine, so ``make demo``, the benchmarks and the
tests start each node as its own process: ``python -m pneumatic_unload.nodes.<name>
--ros-args -p name:=value ...``. This module never imports rclpy; it only runs processes.
Each process writes its output to a log file (a pipe could fill up and block the node).
"""

from __future__ import annotations

import functools
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

#: Domain ids tried by :func:`free_domain_id` (0 is everybody's default).
DOMAIN_RANGE = (1, 101)


def _domain_looks_free(domain_id: int) -> bool:
    """True when no DDS participant on this host holds the domain's discovery ports."""
    base = 7400 + 250 * domain_id
    for port in (base, base + 10):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("", port))  # no SO_REUSEADDR: fails while a participant holds it
            except OSError:
                return False
    return True


def free_domain_id() -> int:
    """A ROS_DOMAIN_ID that no other DDS participant on this host uses (best effort)."""
    lo, hi = DOMAIN_RANGE
    span = hi - lo + 1
    start = (os.getpid() + random.SystemRandom().randrange(span)) % span
    candidates = [lo + (start + k) % span for k in range(span)]
    return next((d for d in candidates if _domain_looks_free(d)), candidates[0])


def ros_args(params: dict[str, Any]) -> list[str]:
    """``-p name:=value`` arguments (bools as true/false, lists as YAML lists)."""
    out: list[str] = []
    for k, v in params.items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, (list, tuple)):
            v = "[" + ",".join(repr(x) for x in v) + "]"
        out += ["-p", f"{k}:={v}"]
    return out


@functools.cache
def _env_resets_signals() -> bool:
    """The system's ``env`` has ``--default-signal`` (coreutils 8.31 and later)."""
    if shutil.which("env") is None:
        return False
    try:
        return subprocess.run(["env", "--default-signal=INT,TERM", "true"],
                              capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


class NodeProcess:
    """A node of this package in its own process, its output in a log file.

    Parameters
    ----------
    name : str
        Node module: simulator, estimator, recorder or replay.
    params : dict
        ROS parameters.
    log_dir : Path
        Folder of the log file.
    extra : list of str
        More ``--ros-args`` arguments (e.g. ``--params-file FILE``).
    env : dict
        Environment (default: this process's).
    """

    def __init__(self, name: str, params: dict[str, Any] | None = None,
                 log_dir: Path | None = None, extra: list[str] | None = None,
                 env: dict[str, str] | None = None) -> None:
        # -P: the working directory is not put first on sys.path (python -m would): a node
        # started from a checkout, or from a folder holding an old copy, runs the package
        # this Python has (PYTHONPATH's, else the installed one)
        args = [sys.executable, "-P", "-m", f"pneumatic_unload.nodes.{name}", "--ros-args",
                *ros_args(params or {}), *(extra or [])]
        if _env_resets_signals():
            # SIGINT and SIGTERM at their defaults in the node (a launcher run as a shell's
            # background job has SIGINT ignored, which a child inherits: a stop in the
            # node's first ~50 ms, before its own handler, would be lost)
            args = ["env", "--default-signal=INT,TERM", *args]
        self.name = name
        log_dir = log_dir or Path("/tmp")
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = log_dir / f"{name}-{os.getpid()}-{time.time_ns()}.log"
        self._log = open(self.log_path, "w")
        self.proc = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                     env=env if env is not None else os.environ.copy())
        self.returncode: int | None = None

    def output(self) -> str:
        """Everything the node printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def wait_output(self, pattern: str, timeout: float) -> re.Match[str]:
        """Wait until the output matches ``pattern`` (regex); AssertionError after timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = re.search(pattern, self.output())
            if m:
                return m
            if self.proc.poll() is not None:
                m = re.search(pattern, self.output())
                if m:
                    return m
                break
            time.sleep(0.05)
        raise AssertionError(f"{self.name}: no {pattern!r} within {timeout} s; output:\n"
                             f"{self.output()[-3000:]}")

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """Send ``sig`` and wait for the exit code (AssertionError and kill after timeout)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                raise AssertionError(f"{self.name} did not stop on {sig!r}:\n"
                                     f"{self.output()[-3000:]}") from None
        self.returncode = self.proc.returncode
        if not self._log.closed:
            self._log.close()
        return self.returncode


# --------------------------------------------------------------------------- launch files
#: Substitutions of the ROS 2 launch format this launcher resolves.
SUBSTITUTION = re.compile(r"\$\((var|find-pkg-share|env)\s+([^)\s]+)(?:\s+([^)]*))?\)")
#: The package whose share folder ``$(find-pkg-share ...)`` resolves here.
PACKAGE = "pneumatic_unload"
#: The node executables of the package (its console scripts and node modules).
EXECUTABLES = ("simulator", "estimator", "recorder", "replay", "opcua")


class LaunchError(ValueError):
    """A launch file this launcher cannot run, with the reason."""


def package_share(package: str = PACKAGE) -> Path:
    """The share folder of the package: the source tree beside this module (``config/``
    there), else the installed ``share/<package>`` (ament index).

    Raises
    ------
    LaunchError
        Another package, or none found."""
    if package != PACKAGE:
        raise LaunchError(f"$(find-pkg-share {package}): only {PACKAGE} is known here")
    root = Path(__file__).resolve().parents[2]
    if (root / "config" / "estimator.yaml").is_file():
        return root
    for prefix in [*os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep), sys.prefix]:
        share = Path(prefix) / "share" / package
        if (share / "config").is_dir():
            return share
    raise LaunchError(f"no share folder of {package} (config/ not found)")


def _substitute(text: Any, args: dict[str, str]) -> Any:
    """``text`` with its substitutions resolved (non-strings as they are)."""
    if not isinstance(text, str):
        return text

    def one(m: re.Match[str]) -> str:
        kind, name, rest = m.group(1), m.group(2), m.group(3)
        if kind == "var":
            if name not in args:
                raise LaunchError(f"$(var {name}): no such argument (declared: "
                                  f"{', '.join(sorted(args)) or 'none'})")
            return args[name]
        if kind == "env":
            value = os.environ.get(name, rest)
            if value is None:
                raise LaunchError(f"$(env {name}): not set and no default")
            return value
        return str(package_share(name))
    return SUBSTITUTION.sub(one, text)


def _condition(text: Any, args: dict[str, str], what: str) -> bool:
    """A node's ``if``/``unless`` value as ROS reads it: 'true'/'false' or '1'/'0' (any
    case) once its substitutions are resolved.

    Raises
    ------
    LaunchError
        Any other value."""
    value = str(_substitute(str(text), args)).strip().lower()
    if value in ("true", "1"):
        return True
    if value in ("false", "0"):
        return False
    raise LaunchError(f"{what}: {text!r} is {value!r}, not true or false")


#: The ``type`` identifiers of a launch file's ``param`` (launch's frontend
#: ``get_data_type_from_identifier``): the scalar types a value is coerced to.
PARAM_TYPES = {"str": str, "int": int, "float": float, "bool": bool}


def _typed(text: Any, type_id: str | None = None, what: str = "param") -> Any:
    """A parameter value as launch_ros reads it from a launch file: without a ``type``,
    the YAML type of its text (``2000`` an integer, ``2000.0`` a double: a node whose
    parameter is a double refuses the integer, as under ``ros2 launch``); with ``type:
    float`` both ``2000`` and ``2000.0`` are doubles, ``int`` and ``str`` likewise; an
    empty string kept.

    Raises
    ------
    LaunchError
        A type identifier launch does not know, or a text that is not of the type."""
    if type_id is not None and type_id != "yaml":
        if type_id not in PARAM_TYPES:
            raise LaunchError(f"{what}: type {type_id!r} is not one of "
                              f"{', '.join(PARAM_TYPES)}, yaml")
        kind = PARAM_TYPES[type_id]
        if kind is str:
            return str(text)
        if kind in (int, float):
            try:
                return kind(str(text))
            except ValueError:
                raise LaunchError(f"{what}: {text!r} is not of type {type_id}") from None
        value = {"1": "true", "0": "false"}.get(str(text), str(text)).strip().lower()
        if value not in ("true", "false"):
            raise LaunchError(f"{what}: {text!r} is not of type bool")
        return value == "true"
    if not isinstance(text, str) or text == "":
        return text
    import yaml

    value = yaml.safe_load(text)
    return text if value is None else value


def load_launch(path: str | Path, overrides: dict[str, str] | None = None
                ) -> list[dict[str, Any]]:
    """The nodes of a ROS 2 YAML launch file, its arguments set from ``overrides``
    (``name:=value`` of the command line) or their defaults: per node its ``exec``,
    ``name``, parameter files and parameter values (typed as launch_ros types them: a
    ``param``'s ``type`` if given, else the YAML type of its text); a node whose
    ``if`` is false (or ``unless`` true) is left out.

    Raises
    ------
    LaunchError
        Not a launch file, an unknown entry or argument, a missing value, another package
        or executable."""
    import yaml

    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise LaunchError(f"{path}: cannot read the launch file: {exc}") from exc
    if not isinstance(doc, dict) or not isinstance(doc.get("launch"), list):
        raise LaunchError(f"{path}: not a ROS 2 YAML launch file (no 'launch:' list)")
    given = dict(overrides or {})
    args: dict[str, str] = {}
    nodes = []
    for entry in doc["launch"]:
        if not isinstance(entry, dict) or len(entry) != 1:
            raise LaunchError(f"{path}: an entry is not one 'arg' or 'node': {entry!r}")
        (kind, body), = entry.items()
        if kind == "arg":
            name = str(body.get("name", ""))
            if name in given:
                args[name] = str(given.pop(name))
            elif "default" in body:
                args[name] = _substitute(str(body["default"]), args)
            else:
                raise LaunchError(f"argument {name!r} has no default: give {name}:=VALUE")
        elif kind == "node":
            if body.get("pkg") != PACKAGE or body.get("exec") not in EXECUTABLES:
                raise LaunchError(f"node {body.get('pkg')}/{body.get('exec')}: this "
                                  f"launcher runs {PACKAGE}'s {', '.join(EXECUTABLES)}")
            what = f"node {body.get('name', body['exec'])}"
            if "if" in body and not _condition(body["if"], args, f"{what} if"):
                continue
            if "unless" in body and _condition(body["unless"], args, f"{what} unless"):
                continue
            files, values = [], {}
            for p in body.get("param", []) or []:
                if "from" in p:
                    files.append(Path(_substitute(p["from"], args)))
                else:
                    values[str(p["name"])] = _typed(_substitute(p.get("value"), args),
                                                    p.get("type"),
                                                    f"{what} param {p['name']}")
            nodes.append({"exec": body["exec"], "name": body.get("name", body["exec"]),
                          "files": files, "params": values})
        else:
            raise LaunchError(f"{path}: entry {kind!r} is not supported here (arg, node)")
    if given:
        raise LaunchError(f"unknown launch argument(s) {', '.join(sorted(given))}; "
                          f"declared: {', '.join(sorted(args))}")
    return nodes


def start_launch(nodes: list[dict[str, Any]], log_dir: Path,
                 env: dict[str, str] | None = None) -> list[NodeProcess]:
    """Start the nodes of :func:`load_launch`, each in its own process, with ``env``
    (default this environment: its ``ROS_DOMAIN_ID``): its parameter files, then its
    values (written to a parameter file of its own in ``log_dir``: a ``-p name:=`` of an
    empty string is no valid override), then its name."""
    import yaml

    log_dir.mkdir(parents=True, exist_ok=True)
    procs = []
    for n in nodes:
        extra: list[str] = []
        for f in n["files"]:
            extra += ["--params-file", str(f)]
        if n["params"]:
            own = log_dir / f"{n['name']}-{os.getpid()}-launch.yaml"
            own.write_text(yaml.safe_dump({"/**": {"ros__parameters": n["params"]}}))
            extra += ["--params-file", str(own)]
        if n["name"] != n["exec"]:
            extra += ["-r", f"__node:={n['name']}"]
        procs.append(NodeProcess(n["exec"], {}, log_dir, extra=extra, env=env))
    return procs


def main(argv: list[str] | None = None) -> int:
    """``python -m pneumatic_unload.app.launch FILE [name:=value ...]``: run a launch file's
    nodes until Ctrl-C (or one of them exits); exit code 0 when all stopped cleanly."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: python -m pneumatic_unload.app.launch FILE.launch.yaml [name:=value ...]")
        return 0 if argv else 2
    overrides = {}
    for a in argv[1:]:
        if ":=" not in a:
            print(f"launch: {a!r} is not name:=value", file=sys.stderr)
            return 2
        k, v = a.split(":=", 1)
        overrides[k] = v
    try:
        nodes = load_launch(argv[0], overrides)
    except LaunchError as exc:
        print(f"launch: {exc}", file=sys.stderr)
        return 2
    log_dir = Path(os.environ.get("PNEUMATIC_UNLOAD_LOG_DIR", "runs/logs"))

    def interrupt(_sig: int, _frame: Any) -> None:
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, interrupt)  # a supervisor's stop: as Ctrl-C
    # SIGINT's handler set here too: a launcher started as a shell script's background job
    # has SIGINT ignored, and Python then installs none (a `kill -INT` did nothing)
    signal.signal(signal.SIGINT, interrupt)
    procs = start_launch(nodes, log_dir)
    print(f"launch: {', '.join(n['name'] for n in nodes)} started on ROS_DOMAIN_ID="
          f"{os.environ.get('ROS_DOMAIN_ID', '0')}; logs in {log_dir}/; Ctrl-C stops them",
          flush=True)
    try:
        while all(p.proc.poll() is None for p in procs):
            time.sleep(0.2)
        for p in procs:
            if p.proc.poll() is not None:
                print(f"launch: {p.name} exited with code {p.proc.returncode}; its log "
                      f"{p.log_path}:\n{p.output()[-1500:]}", file=sys.stderr)
    except KeyboardInterrupt:
        pass
    # stopping: the nodes get one SIGINT each from here (a terminal's Ctrl-C reached them
    # too; a second one to the launcher must not cut their shutdown short)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    codes = []
    for p in reversed(procs):
        try:
            codes.append(p.stop())
        except AssertionError as exc:
            print(f"launch: {exc}", file=sys.stderr)
            codes.append(1)
    return 0 if all(c == 0 for c in codes) else 1


if __name__ == "__main__":
    sys.exit(main())
