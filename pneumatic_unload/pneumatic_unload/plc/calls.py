# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Method calls that take tens of seconds without stalling the caller's session.

asyncua's server handles the requests of one connection strictly one after the other: a
``Measure`` call awaited there would hold back every later request of that connection for
the whole measurement (tens of seconds), among them the reads a client's watchdog makes
every second (asyncua's client reads the server state each ``watchdog_intervall`` = 1 s and
drops the connection when no answer comes within it). So Call requests are answered in a
task of their own: the connection's other requests (reads, subscriptions' publish requests,
keep-alives) go on meanwhile, and the call's response is sent when it is ready (OPC UA
matches a response to its request by the request id, in any order).

The same processor guards the session services of a plant's server (:mod:`.security`):

* CreateSession: the client certificate validated is the one its secure channel was opened
  with (the one whose key the channel proves; asyncua validates the certificate the request
  names, a public document any client can copy, and none when the request names none); a
  request naming another certificate is refused (BadCertificateInvalid);
* ActivateSession with a user name: the password is checked by
  :meth:`.security.Users.verify` (a worker thread, the peer's backoff) before asyncua
  activates the session, so asyncua's synchronous user hook never hashes on the event loop.

asyncua offers no hook for its per-connection request processor, so :func:`install` puts
:class:`ConcurrentCalls` (a subclass of asyncua's ``UaProcessor`` that changes only where a
Call request is awaited and what is checked before a session is created or activated) in
the place of asyncua's processor class: for every server of the process (the bridge's
process runs one); a server whose user manager is not :class:`.security.Users` keeps
asyncua's own session checks. A test of the bridge holds a client with the
default 1 s watchdog through a whole ``Measure`` call, so an asyncua release that changes
the processor breaks a test, not a plant.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import User
from asyncua.server import binary_server_asyncio
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua.ua_binary import nodeid_from_binary, struct_from_binary
from cryptography import x509

from pneumatic_unload.plc.security import LOGIN_VERDICT, Users

_CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
_CREATE = ua.NodeId(ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary)
_ACTIVATE = ua.NodeId(ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary)
_log = logging.getLogger(__name__)


class ConcurrentCalls(UaProcessor):
    """asyncua's request processor of a connection, its Call requests answered each in a
    task of its own (see the module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._calls: set[asyncio.Task[Any]] = set()

    async def process_message(self, seqhdr: Any, body: Any) -> Any:
        """A request: a Call in a task (True at once: the connection stays open), a
        session's creation or activation after the bridge's checks, any other as asyncua
        answers it."""
        typeid = nodeid_from_binary(body.copy())
        if typeid == _CREATE:
            refused = await self._channel_certificate(body)
            if refused is not None:
                return self._fault(seqhdr, body, refused)
        elif typeid == _ACTIVATE:
            token = LOGIN_VERDICT.set(await self._verify_login(body))
            try:
                return await super().process_message(seqhdr, body)
            finally:
                LOGIN_VERDICT.reset(token)
        if typeid != _CALL:
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


    def _fault(self, seqhdr: Any, body: Any, code: int) -> bool:
        """Answer a request with a service fault of ``code`` (the connection stays
        open)."""
        buf = body.copy()
        nodeid_from_binary(buf)
        requesthdr = struct_from_binary(ua.RequestHeader, buf)
        response = ua.ServiceFault()
        response.ResponseHeader.ServiceResult = ua.StatusCode(code)
        _log.warning("session refused to %s: %s", self.name, ua.StatusCode(code).name)
        self.send_response(requesthdr.RequestHandle, seqhdr, response)
        return True

    async def _channel_certificate(self, body: Any) -> int | None:
        """None when a CreateSession request may go on; else the status code refusing it:
        with a certificate validator (a plant), the secure channel's client certificate
        must pass it and be the one the request names."""
        validator = self.iserver.certificate_validator
        if validator is None or not isinstance(self.iserver.user_manager, Users):
            return None
        buf = body.copy()
        nodeid_from_binary(buf)
        struct_from_binary(ua.RequestHeader, buf)
        params = struct_from_binary(ua.CreateSessionParameters, buf)
        channel = self._connection.security_policy.peer_certificate
        if channel is None:
            return ua.StatusCodes.BadSecurityChecksFailed  # no certificate: not a plant's
        if params.ClientCertificate and params.ClientCertificate != channel:
            return ua.StatusCodes.BadCertificateInvalid
        try:
            await validator(x509.load_der_x509_certificate(channel), params.ClientDescription)
        except ServiceError as exc:
            return int(exc.code)
        except ValueError:
            return ua.StatusCodes.BadCertificateInvalid
        return None

    async def _verify_login(self, body: Any) -> tuple[str, str, User | None] | None:
        """The verdict of an ActivateSession's user name and password, checked off the
        event loop (:meth:`Users.verify`) before asyncua activates the session; None
        without a user name (anonymous), with another user manager, or with a token
        asyncua itself refuses."""
        users = self.iserver.user_manager
        if not isinstance(users, Users) or self.session is None:
            return None
        buf = body.copy()
        nodeid_from_binary(buf)
        struct_from_binary(ua.RequestHeader, buf)
        try:
            params = struct_from_binary(ua.ActivateSessionParameters, buf)
            token = params.UserIdentityToken
            if not isinstance(token, ua.UserNameIdentityToken):
                return None
            username, password = self.iserver.decrypt_user_token(self.session, token)
        except Exception:  # malformed: asyncua answers it (BadIdentityTokenInvalid)
            return None
        peer = str(self.name[0]) if isinstance(self.name, tuple) else str(self.name)
        username, password = username or "", password or ""
        return username, password, await users.verify(peer, username, password)


def install() -> None:
    """Use :class:`ConcurrentCalls` for the connections of every asyncua server of this
    process from now on (idempotent)."""
    binary_server_asyncio.UaProcessor = ConcurrentCalls  # type: ignore[misc]
