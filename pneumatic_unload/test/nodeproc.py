# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Helpers of the multi-process node tests (nodes run via :mod:`pneumatic_unload.app.launch`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from pneumatic_unload.app.launch import NodeProcess

__all__ = ["NodeProcess", "spin_until"]


def spin_until(node: Any, executor: Any, cond: Callable[[], bool], timeout: float) -> bool:
    """Spin ``executor`` until ``cond()`` or ``timeout`` [s]; return cond()."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        executor.spin_once(timeout_sec=0.05)
    return cond()
