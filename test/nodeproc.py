"""Helpers of the multi-process node tests: start nodes as processes, stop them, observe.

Every node runs in its own process (``python -m pneumatic_unload.nodes.<name> --ros-args
...``) over real DDS, with the test run's ROS_DOMAIN_ID (see conftest.py).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


class NodeProcess:
    """A node in its own process; its output goes to a log file (no pipe can fill up)."""

    def __init__(self, name: str, params: dict[str, Any] | None = None,
                 log_dir: Path | None = None, extra: list[str] | None = None) -> None:
        args = [sys.executable, "-m", f"pneumatic_unload.nodes.{name}", "--ros-args"]
        for k, v in (params or {}).items():
            if isinstance(v, bool):
                v = "true" if v else "false"
            args += ["-p", f"{k}:={v}"]
        args += extra or []
        self.name = name
        self.log_path = (log_dir or Path("/tmp")) / f"{name}-{os.getpid()}-{time.time_ns()}.log"
        self._log = open(self.log_path, "w")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                     cwd=REPO, env=os.environ.copy())
        self.returncode: int | None = None

    def output(self) -> str:
        """Everything the node printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text()

    def wait_output(self, pattern: str, timeout: float) -> re.Match[str]:
        """Wait until the output matches ``pattern`` (regex)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = re.search(pattern, self.output())
            if m:
                return m
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(f"{self.name}: no {pattern!r} within {timeout} s; output:\n"
                             f"{self.output()[-3000:]}")

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """Send ``sig`` and wait for the exit code (kill after ``timeout``)."""
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
        self._log.close()
        return self.returncode


def spin_until(node: Any, executor: Any, cond: Callable[[], bool], timeout: float) -> bool:
    """Spin ``executor`` until ``cond()`` or ``timeout`` [s]; return cond()."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        executor.spin_once(timeout_sec=0.05)
    return cond()
