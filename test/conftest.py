"""Shared pytest setup for pneumatic_unload.

At import time (before any test module can import rclpy) every test run gets its own
ROS_DOMAIN_ID, exported in os.environ so that spawned node processes inherit it: two test
runs on one machine otherwise see each other's topics. Set PNEUMATIC_UNLOAD_KEEP_DOMAIN to
keep the ROS_DOMAIN_ID of the environment. Keep this file small and generic.
"""

import os
import random
import socket
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

# Domain ids 1..101: 0 is everybody's default, and the RTPS well-known ports
# (7400 + 250 * id, +10 for the first participant's unicast port) stay far below 65535.
_DOMAIN_MIN, _DOMAIN_MAX = 1, 101


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


def _pick_domain_id() -> int:
    span = _DOMAIN_MAX - _DOMAIN_MIN + 1
    start = (os.getpid() + random.SystemRandom().randrange(span)) % span
    candidates = [_DOMAIN_MIN + (start + k) % span for k in range(span)]
    return next((d for d in candidates if _domain_looks_free(d)), candidates[0])


if not os.environ.get("PNEUMATIC_UNLOAD_KEEP_DOMAIN"):
    os.environ["ROS_DOMAIN_ID"] = str(_pick_domain_id())
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")


def pytest_report_header(config: pytest.Config) -> str:
    return (
        f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '(unset)')} "
        f"RMW_IMPLEMENTATION={os.environ['RMW_IMPLEMENTATION']}"
    )


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """Root of the pneumatic_unload repository (the folder holding package.xml)."""
    return REPO_ROOT


@pytest.fixture(scope="session")
def venv_python() -> Path:
    """The interpreter running the tests (the project's venv python)."""
    return Path(sys.executable)
