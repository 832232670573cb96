# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Shared pytest setup for pneumatic_unload.

At import time (before any test module can import rclpy) every test run gets its own
ROS_DOMAIN_ID, exported in os.environ so that spawned node processes inherit it: two test
runs on one machine otherwise see each other's topics. Set PNEUMATIC_UNLOAD_KEEP_DOMAIN to
keep the ROS_DOMAIN_ID of the environment. numpy's BLAS runs on one thread here as in the
package's programs (:func:`pneumatic_unload.single_threaded_blas`, before numpy is first
imported), so that what a test computes in process is what a node computes. Keep this file
small and generic.

``make test`` runs the suite in two parts: the tests not marked ``serial`` on every core
(pytest-xdist), then the ``serial`` ones alone: node processes over DDS in real time,
servers on ports, kill -9 and latency bounds, which a parallel worker's load
would slow or share the machine with. A module with any of these carries
``pytestmark = pytest.mark.serial`` (``test_layout.py`` checks it).
"""

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from pneumatic_unload import single_threaded_blas

single_threaded_blas()
assert "numpy" not in sys.modules, "numpy's BLAS threads are set before numpy is imported"

import pytest  # noqa: E402
from pgserver import pg_server, pg_url  # noqa: E402, F401  (one PostgreSQL per session)

from pneumatic_unload.app.launch import free_domain_id  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[1]

if not os.environ.get("PNEUMATIC_UNLOAD_KEEP_DOMAIN"):
    os.environ["ROS_DOMAIN_ID"] = str(free_domain_id())
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "serial: run alone, after the parallel part of make test (real-time node "
        "processes, servers, timings)")


def _suite_run(config: pytest.Config) -> bool:
    """No ``-m`` given and only folders named (``pytest test``; colcon test's run of the
    package): the run of the whole suite, whose serial tests ``make test`` runs on their
    own."""
    paths = [a.split("::")[0] for a in config.args]
    return not config.option.markexpr and all(Path(p).is_dir() for p in paths)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # a suite run without -m (colcon test) runs the tests not marked serial: those start
    # node processes and servers in real time and need the machine alone (make test runs
    # them after the rest, -m serial); a file or test named runs as asked
    if not _suite_run(config):
        return
    serial = [it for it in items if it.get_closest_marker("serial")]
    if serial:
        config.hook.pytest_deselected(items=serial)
        items[:] = [it for it in items if not it.get_closest_marker("serial")]


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


@pytest.fixture()
def ros_node() -> Iterator[tuple[Any, Any]]:
    """An rclpy context and observer node in this process, with its executor (torn down
    after the test): the node tests' view of the DDS graph."""
    import time

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node(f"observer_{time.time_ns()}", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    yield node, ex
    ex.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
