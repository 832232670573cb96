"""Method calls that take tens of seconds without stalling the caller's session.

asyncua's server handles the requests of one connection strictly one after the other: a
``Measure`` call awaited there would hold back every later request of that connection for
the whole measurement (tens of seconds), among them the reads a client's watchdog makes
every second (asyncua's client reads the server state each ``watchdog_intervall`` = 1 s and
drops the connection when no answer comes within it). So Call requests are answered in a
task of their own: the connection's other requests (reads, subscriptions' publish requests,
keep-alives) go on meanwhile, and the call's response is sent when it is ready (OPC UA
matches a response to its request by the request id, in any order).

asyncua offers no hook for its per-connection request processor, so :func:`install` puts
:class:`ConcurrentCalls` (a subclass of asyncua's ``UaProcessor`` that changes only where a
Call request is awaited) in the place of asyncua's processor class: for every server of
the process (the bridge's process runs one). A test of the bridge holds a client with the
default 1 s watchdog through a whole ``Measure`` call, so an asyncua release that changes
the processor breaks a test, not a plant.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from asyncua import ua
from asyncua.server import binary_server_asyncio
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua.ua_binary import nodeid_from_binary

_CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
_log = logging.getLogger(__name__)


class ConcurrentCalls(UaProcessor):
    """asyncua's request processor of a connection, its Call requests answered each in a
    task of its own (see the module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._calls: set[asyncio.Task[Any]] = set()

    async def process_message(self, seqhdr: Any, body: Any) -> Any:
        """A request: a Call in a task (True at once: the connection stays open), any
        other as asyncua answers it."""
        if nodeid_from_binary(body.copy()) != _CALL:
            return await super().process_message(seqhdr, body)
        task = asyncio.get_running_loop().create_task(self._answer(seqhdr, body))
        self._calls.add(task)
        task.add_done_callback(self._calls.discard)
        return True

    async def _answer(self, seqhdr: Any, body: Any) -> None:
        """Answer one Call request (asyncua's processing: its checks, the method, the
        response or a service fault); a connection lost meanwhile is logged, not raised."""
        try:
            await super().process_message(seqhdr, body)
        except Exception as exc:  # the response could not be sent (connection gone)
            _log.warning("a method call's response was not sent: %s: %s",
                         type(exc).__name__, exc)


def install() -> None:
    """Use :class:`ConcurrentCalls` for the connections of every asyncua server of this
    process from now on (idempotent)."""
    binary_server_asyncio.UaProcessor = ConcurrentCalls  # type: ignore[misc]
