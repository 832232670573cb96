# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Security of the OPC UA bridge: who may connect, and who may start a measurement.

Secure by default: the bridge listens on loopback unless told another address (the
node's ``endpoint``), and an anonymous session may browse, read and subscribe but its Call
requests (every method: a measurement opens the rig's valve) are answered
``BadUserAccessDenied`` unless ``allow_anonymous`` is set (a lab bench). Two set-ups,
chosen by :class:`Security`:

* a lab bench: policy ``None`` (no certificates), ``allow_anonymous`` true: every session
  may call the methods;
* a plant: policy ``Basic256Sha256`` with ``SignAndEncrypt`` (the server's certificate and
  private key given), a trust list (``trusted_certs``: the client certificates, or the CAs
  of the client certificates, accepted; the bridge does not start without one), user names
  with passwords from a users file: only a configured user may call a method. A client's
  certificate is validated when it creates its session (the one its secure channel was
  opened with): within its validity dates, trusted, not revoked, its URI, key usage and
  client role (asyncua's :class:`~asyncua.crypto.validator.CertificateValidator`); an
  expired, not yet valid or untrusted certificate gets no session.

A login costs the same for a known and an unknown user name (an unknown one is checked
against a dummy hash of as many PBKDF2 iterations, compared in constant time); the hash
runs in a worker thread (:data:`HASH_WORKERS`), never on the server's event loop, and a
peer's logins are taken one at a time, each after a delay that doubles with the peer's
consecutive failures (:data:`FREE_FAILURES`, :data:`BACKOFF_FIRST`, :data:`BACKOFF_MAX`):
a wrong-password flood slows itself down and cannot stall the sessions already open.

Passwords are never stored: the users file holds one ``name:HASH`` line per user, the hash
made by :func:`hash_password` (PBKDF2-HMAC-SHA256, salted)::

    python -m pneumatic_unload.plc.security operator >> users.txt   # asks for the password
"""

from __future__ import annotations

import asyncio
import contextvars
import getpass
import hashlib
import hmac
import secrets
import sys
import time
from collections import OrderedDict
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from asyncua import ua
from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, User, UserRole

#: The security policies offered (parameter ``security_policy``).
POLICIES = ("None", "Basic256Sha256")
#: Iterations of PBKDF2 of a new hash [-].
ITERATIONS = 100_000
#: Longest string argument of a method (PartId) [characters]: a part's id, a serial
#: number or a DMC code is tens of characters; a longer one is answered BadInvalidArgument
#: (it would go to the log and the results database as it is).
MAX_STRING = 256
#: Largest OPC UA request the server accepts [bytes] (asyncua's default is 100 MiB): the
#: bridge's requests (reads, browses, a method call with its PartId) are a few kB; a larger
#: one is refused by the transport before it is decoded.
MAX_MESSAGE = 1 << 20
#: Threads that hash passwords (PBKDF2 off the server's event loop) [-].
HASH_WORKERS = 2
#: Consecutive failed logins of a peer (its IP address) answered without delay (typing
#: errors) [-].
FREE_FAILURES = 3
#: Delay before a peer's next login after its first failure beyond FREE_FAILURES, doubled
#: with each further failure [s].
BACKOFF_FIRST = 0.5
#: Longest delay before a peer's login [s].
BACKOFF_MAX = 8.0
#: A peer's failures are forgotten this long after its last one [s].
BACKOFF_FORGET = 300.0
#: Peers whose failures are kept (the oldest forgotten first) [-].
PEERS_KEPT = 1024
_SCHEME = "pbkdf2_sha256"
_CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
_SESSION_TYPES = frozenset(ua.NodeId(t) for t in USER_TYPES)


class SecurityError(ValueError):
    """A security setting the bridge cannot start with, with the reason."""


def hash_password(password: str, *, salt: bytes | None = None,
                  iterations: int = ITERATIONS) -> str:
    """``pbkdf2_sha256$ITERATIONS$SALT$HASH`` (hex) of a password, for a users file."""
    salt = secrets.token_bytes(16) if salt is None else salt
    digest = hashlib.pbkdf2_hmac("sha256", password.encode(), salt, iterations)
    return f"{_SCHEME}${iterations}${salt.hex()}${digest.hex()}"


def check_password(password: str, stored: str) -> bool:
    """True when ``password`` matches a hash of :func:`hash_password` (constant time)."""
    try:
        scheme, iterations, salt, digest = stored.split("$")
        if scheme != _SCHEME:
            return False
        mine = hashlib.pbkdf2_hmac("sha256", password.encode(), bytes.fromhex(salt),
                                   int(iterations))
    except ValueError:
        return False
    try:
        theirs = bytes.fromhex(digest)
    except ValueError:
        return False
    return hmac.compare_digest(mine, theirs)


def _iterations(stored: str) -> int:
    """The PBKDF2 iteration count of a stored hash (:data:`ITERATIONS` when unreadable)."""
    try:
        return int(stored.split("$")[1])
    except (IndexError, ValueError):
        return ITERATIONS


def load_users(path: str | Path) -> dict[str, str]:
    """The users of a users file: ``name:HASH`` lines (``#`` comments, blank lines).

    Raises
    ------
    SecurityError
        Unreadable file, a line that is not ``name:HASH``, a name given twice, no user."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise SecurityError(f"users file {path}: {exc}") from exc
    users: dict[str, str] = {}
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        name, _, stored = line.partition(":")
        name = name.strip()
        if not name or not stored.startswith(_SCHEME + "$") or stored.count("$") != 3:
            raise SecurityError(f"users file {path}, line {n}: not 'name:{_SCHEME}$...' "
                                "(make the line with python -m pneumatic_unload.plc.security "
                                "NAME)")
        if name in users:
            raise SecurityError(f"users file {path}, line {n}: user {name!r} given twice")
        users[name] = stored
    if not users:
        raise SecurityError(f"users file {path}: no user in it")
    return users


@dataclass(frozen=True)
class Security:
    """The bridge's security settings.

    Attributes
    ----------
    policy : str
        'None' (a lab bench) or 'Basic256Sha256' (SignAndEncrypt only: a plant).
    certificate, private_key : str
        The server's certificate (DER or PEM) and private key (PEM) files; required by
        Basic256Sha256.
    users : dict
        User name -> password hash (:func:`hash_password`): the users who may call the
        methods.
    allow_anonymous : bool
        Anonymous sessions may call the methods (a lab bench; else they may browse, read
        and subscribe only).
    trusted_certs : str
        Folder of the trusted client certificates (or of their CAs), DER or PEM; required
        by Basic256Sha256.
    revoked_certs : str
        Folder of certificate revocation lists (DER or PEM; '' none).
    """

    policy: str = "None"
    certificate: str = ""
    private_key: str = ""
    users: dict[str, str] | None = None
    allow_anonymous: bool = False
    trusted_certs: str = ""
    revoked_certs: str = ""

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise SecurityError(f"security_policy must be one of {POLICIES}, got "
                                f"{self.policy!r}")
        if self.policy != "None" and not (self.certificate and self.private_key):
            raise SecurityError(f"security_policy {self.policy} needs the server's "
                                "certificate and private_key files")
        for what, path in (("certificate", self.certificate),
                           ("private_key", self.private_key)):
            if path and not Path(path).is_file():
                raise SecurityError(f"{what} {path}: no such file")
        if self.users and self.policy == "None":
            raise SecurityError("users need an encrypted channel (security_policy "
                                "Basic256Sha256): with 'None' their passwords would cross "
                                "the network in clear")
        if self.policy == "None" and (self.trusted_certs or self.revoked_certs):
            raise SecurityError("trusted_certs and revoked_certs need security_policy "
                                "Basic256Sha256 (with 'None' no client certificate is "
                                "exchanged)")
        if self.policy != "None" and not self.trusted_certs:
            raise SecurityError(f"security_policy {self.policy} needs a trust list: "
                                "trusted_certs, the folder of the client certificates (or "
                                "their CAs) accepted (OPC UA Part 4, 6.1.3)")
        for what, path in (("trusted_certs", self.trusted_certs),
                           ("revoked_certs", self.revoked_certs)):
            if path and not Path(path).is_dir():
                raise SecurityError(f"{what} {path}: no such folder")
        if self.trusted_certs and not any(
                f.suffix.lower() in (".der", ".pem") for f in Path(self.trusted_certs).iterdir()):
            raise SecurityError(f"trusted_certs {self.trusted_certs}: no certificate (.der "
                                "or .pem) in it")

    def policy_types(self) -> list[ua.SecurityPolicyType]:
        """The endpoints' policies: exactly the one chosen (never None beside a secure
        one)."""
        if self.policy == "None":
            return [ua.SecurityPolicyType.NoSecurity]
        return [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]

    def identity_tokens(self) -> list[type]:
        """The identity token types offered: anonymous (its sessions may call the methods
        only with allow_anonymous), user names (with users)."""
        tokens: list[type] = [ua.AnonymousIdentityToken]
        return tokens + ([ua.UserNameIdentityToken] if self.users else [])


#: The verdict of the login being activated in this task: (user name, password, the user
#: or None) of :meth:`Users.verify`, set by the bridge's request processor
#: (:mod:`.calls`) around asyncua's synchronous activation, read by :meth:`Users.get_user`.
LOGIN_VERDICT: contextvars.ContextVar[tuple[str, str, User | None] | None] = \
    contextvars.ContextVar("pneumatic_unload_login", default=None)


@dataclass
class _Peer:
    """A peer's failed logins: how many in a row, the last one [s, monotonic], and the
    lock that takes its logins one at a time."""

    failures: int = 0
    last: float = 0.0
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)


class Users:
    """The asyncua user manager of :class:`Security`: a configured user with the right
    password is a ``User`` (who may call methods); an anonymous session is a ``User`` with
    ``allow_anonymous`` (the lab bench), else ``Anonymous`` (browse, read, subscribe);
    anything else (a wrong password, an unknown name, a user certificate) is refused.

    :meth:`verify` checks a password in a worker thread with the peer's backoff (the
    bridge's request processor awaits it before asyncua activates the session, see
    :mod:`.calls`); :meth:`get_user`, asyncua's synchronous hook, takes its verdict."""

    def __init__(self, users: dict[str, str] | None, allow_anonymous: bool = False) -> None:
        self._users = dict(users or {})
        self._anonymous = UserRole.User if allow_anonymous else UserRole.Anonymous
        #: The hash an unknown user name is checked against: as many iterations as the
        #: costliest configured hash, so that both cost the same.
        self._dummy = hash_password(secrets.token_hex(16), iterations=max(
            (_iterations(h) for h in self._users.values()), default=ITERATIONS))
        self._peers: OrderedDict[str, _Peer] = OrderedDict()
        self._executor: ThreadPoolExecutor | None = None

    def _check(self, username: str, password: str) -> User | None:
        """The user of a user name and password, else None; an unknown name costs a
        known one's check (the dummy hash)."""
        stored = self._users.get(username)
        ok = check_password(password, self._dummy if stored is None else stored)
        return User(role=UserRole.User, name=username) if ok and stored is not None else None

    def delay(self, peer: str, now: float | None = None) -> float:
        """The wait before ``peer``'s next login [s]: 0 for its first
        :data:`FREE_FAILURES` failures in a row, then :data:`BACKOFF_FIRST` doubled per
        further failure, at most :data:`BACKOFF_MAX`."""
        rec = self._peers.get(peer)
        now = time.monotonic() if now is None else now
        if rec is None or now - rec.last > BACKOFF_FORGET:
            return 0.0
        over = rec.failures - FREE_FAILURES
        return 0.0 if over <= 0 else min(BACKOFF_FIRST * 2.0 ** (over - 1), BACKOFF_MAX)

    def _peer(self, peer: str) -> _Peer:
        rec = self._peers.get(peer)
        if rec is None:
            rec = self._peers[peer] = _Peer()
            while len(self._peers) > PEERS_KEPT:  # the oldest idle peer forgotten
                old = next((k for k, v in self._peers.items() if not v.lock.locked()), None)
                if old is None or old == peer:
                    break
                del self._peers[old]
        self._peers.move_to_end(peer)
        return rec

    async def verify(self, peer: str, username: str, password: str) -> User | None:
        """The user of a login from ``peer`` (its IP address), else None: after the
        peer's backoff (:meth:`delay`), one login of a peer at a time, the hash in a
        worker thread."""
        rec = self._peer(peer)
        async with rec.lock:
            if time.monotonic() - rec.last > BACKOFF_FORGET:
                rec.failures = 0
            wait = self.delay(peer)
            if wait > 0:
                await asyncio.sleep(wait)
            if self._executor is None:
                self._executor = ThreadPoolExecutor(HASH_WORKERS, "opcua-login")
            user = await asyncio.get_running_loop().run_in_executor(
                self._executor, self._check, username, password)
            if user is None:
                rec.failures += 1
                rec.last = time.monotonic()
            else:
                rec.failures = 0
        return user

    def close(self) -> None:
        """Stop the hashing threads."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None

    def get_user(self, iserver: Any, username: str | None = None,
                 password: str | None = None, certificate: Any = None) -> User | None:
        """asyncua's hook at a session's activation (None refuses it). ``certificate`` is
        the secure channel's client certificate (user certificates are not among the
        identity tokens offered: asyncua refuses them before). A user name's verdict is
        :meth:`verify`'s when it checked this login (the bridge's processor), else the
        check runs here."""
        if username is None:
            return User(role=self._anonymous)
        verdict = LOGIN_VERDICT.get()
        if verdict is not None and verdict[:2] == (username, password or ""):
            return verdict[2]
        return self._check(username, password or "")


class CallRules(PermissionRuleset):
    """Requests a session may make: the session services (read, browse, subscribe...) for
    every activated session; Call (the methods) only for a ``User`` (a configured user, or
    an anonymous session with ``allow_anonymous``); never the address-space changes (add
    or delete nodes and references)."""

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        """asyncua's hook before each request of a session."""
        if action_type_id not in _SESSION_TYPES:
            return False
        if action_type_id == _CALL:
            return user is not None and user.role in (UserRole.User, UserRole.Admin)
        return True


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m pneumatic_unload.plc.security NAME``: print a users-file line for NAME
    (the password asked twice, or read from stdin when it is not a terminal)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1 or args[0].startswith("-") or ":" in args[0]:
        print("usage: python -m pneumatic_unload.plc.security NAME  (prints NAME:HASH for "
              "the bridge's users_file)", file=sys.stderr)
        return 2
    if sys.stdin.isatty():
        password = getpass.getpass(f"password of {args[0]}: ")
        if getpass.getpass("again: ") != password:
            print("the passwords differ", file=sys.stderr)
            return 1
    else:
        password = sys.stdin.readline().rstrip("\n")
    if not password:
        print("an empty password is refused", file=sys.stderr)
        return 1
    print(f"{args[0]}:{hash_password(password)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
