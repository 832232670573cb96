# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The ROS 2 nodes: one module each, run as ``python -m pneumatic_unload.nodes.<node>`` or as
the console script ``<node>`` (``ros2 run pneumatic_unload <node>``); :mod:`.common` is their
shared plumbing.

Signals. A node stops on SIGINT (and SIGTERM) at any moment of its life, its start included.
The start is mostly imports (numpy, rclpy, the compiled model: 0.3-1 s, more when the model's
C kernel is compiled on first use), then ``rclpy.init`` and the node's construction. What
went wrong there:

* a SIGINT was lost when the node had inherited SIGINT *ignored* (every background job of a
  shell script does, ``cmd &``): Python keeps an ignored SIGINT ignored, and only
  ``rclpy.init`` took it over; a node stopped before that ran on for ever;
* a KeyboardInterrupt raised in the middle of an import or of a half-built node ended the
  process with a traceback (inside a C extension's initialisation as a misleading
  ImportError, exit status 1), and rclpy's handlers, which shut the context down from a
  thread of their own, made the node being built fail on the invalid context, or an
  EventsExecutor registering the node's callbacks keep some and abort the process at its
  destruction (exit status -6).

So from the import of this package in a node program (before numpy and rclpy are imported)
SIGINT and SIGTERM are *held*: recorded, never acted upon asynchronously. The node is built
whole; :func:`pneumatic_unload.nodes.common.running` then stops it at once if a signal came
meanwhile, and later its loop ends on :func:`pneumatic_unload.nodes.common.ok`: files are
completed, the executor, the node and ROS are shut down in that order, exit status 0, at most
the rest of the start after the signal. A signal that comes before the interpreter reaches
this package (its first ~50 ms) is beyond the package's reach: Python's default handler takes
it, or, if the node inherited SIGINT ignored, it is lost.
"""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path
from types import FrameType

from pneumatic_unload import single_threaded_blas

#: Signals a node holds (see the module docstring).
HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: Signals received while held, in their order of arrival.
_received: list[int] = []


def _record(signum: int, _frame: FrameType | None) -> None:
    """The handler of a held signal: record it."""
    _received.append(signum)


def hold_signals() -> None:
    """Hold SIGINT and SIGTERM: from now on they are recorded (:func:`held_signal`), not acted
    upon (also when inherited ignored). Main thread only (Python's signal handlers are set
    there); elsewhere a no-op."""
    if threading.current_thread() is threading.main_thread():
        for sig in HELD_SIGNALS:
            signal.signal(sig, _record)


def held_signal() -> int | None:
    """The first signal held so far (SIGINT or SIGTERM), None when none came."""
    return _received[0] if _received else None


def node_program() -> str | None:
    """The node this process runs, else None: ``python -m pneumatic_unload.nodes.<node>``
    (while the package is imported for ``-m``, ``sys.argv[0]`` is ``'-m'`` and the module
    follows it in ``sys.orig_argv``) or the node's console script, named after it."""
    nodes = {p.stem for p in Path(__file__).parent.glob("*.py")} - {"__init__", "common"}
    if sys.argv[:1] == ["-m"]:
        module = sys.orig_argv[len(sys.orig_argv) - len(sys.argv)]
        prefix, _, name = module.rpartition(".")
        return name if prefix == __name__ and name in nodes else None
    name = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else ""
    return name if name in nodes else None


if node_program() is not None:
    hold_signals()
    single_threaded_blas()  # before numpy (see pneumatic_unload.single_threaded_blas)
