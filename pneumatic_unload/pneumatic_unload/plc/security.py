"""Security of the OPC UA bridge: who may connect, and who may start a measurement.

Two set-ups, chosen by :class:`Security`:

* a lab bench: policy ``None`` (no certificates), anonymous sessions, every session may
  call ``Measure``/``StartMeasure``;
* a plant: policy ``Basic256Sha256`` with ``SignAndEncrypt`` (the server's certificate and
  private key given), user names with passwords from a users file; anonymous sessions
  (when allowed) may browse, read and subscribe, only a configured user may call a method
  (any other session's Call request is answered ``BadUserAccessDenied``); optionally only
  client certificates of a trust folder are accepted.

Passwords are never stored: the users file holds one ``name:HASH`` line per user, the hash
made by :func:`hash_password` (PBKDF2-HMAC-SHA256, salted)::

    python -m pneumatic_unload.plc.security operator >> users.txt   # asks for the password
"""

from __future__ import annotations

import getpass
import hashlib
import hmac
import secrets
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import ua
from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, User, UserRole

#: The security policies offered (parameter ``security_policy``).
POLICIES = ("None", "Basic256Sha256")
#: Iterations of PBKDF2 of a new hash [-].
ITERATIONS = 100_000
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
    return hmac.compare_digest(mine.hex(), digest)


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
        'None' (a lab bench) or 'Basic256Sha256' (SignAndEncrypt only).
    certificate, private_key : str
        The server's certificate (DER or PEM) and private key (PEM) files; required by
        Basic256Sha256.
    users : dict
        User name -> password hash (:func:`hash_password`); empty: every session may call
        the methods.
    allow_anonymous : bool
        Anonymous sessions may connect (with users configured: browse, read, subscribe).
    trusted_certs : str
        Folder of the client certificates accepted ('' accepts any client certificate).
    """

    policy: str = "None"
    certificate: str = ""
    private_key: str = ""
    users: dict[str, str] | None = None
    allow_anonymous: bool = True
    trusted_certs: str = ""

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
        if not self.users and not self.allow_anonymous:
            raise SecurityError("allow_anonymous false needs users (users_file)")
        if self.trusted_certs and not Path(self.trusted_certs).is_dir():
            raise SecurityError(f"trusted_certs {self.trusted_certs}: no such folder")

    def policy_types(self) -> list[ua.SecurityPolicyType]:
        """The endpoints' policies: exactly the one chosen (never None beside a secure
        one)."""
        if self.policy == "None":
            return [ua.SecurityPolicyType.NoSecurity]
        return [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]

    def identity_tokens(self) -> list[type]:
        """The identity token types offered: anonymous (when allowed), user names (with
        users)."""
        tokens: list[type] = [ua.AnonymousIdentityToken] if self.allow_anonymous else []
        return tokens + ([ua.UserNameIdentityToken] if self.users else [])


class Users:
    """The asyncua user manager of :class:`Security`: a configured user with the right
    password is a ``User`` (who may call methods); an anonymous session is a ``User``
    without configured users (the lab bench), else ``Anonymous``; anything else (a wrong
    password, an unknown name, a user certificate) is refused."""

    def __init__(self, users: dict[str, str] | None) -> None:
        self._users = dict(users or {})

    def get_user(self, iserver: Any, username: str | None = None,
                 password: str | None = None, certificate: Any = None) -> User | None:
        """asyncua's hook at a session's activation (None refuses it). ``certificate`` is
        the secure channel's client certificate (user certificates are not among the
        identity tokens offered: asyncua refuses them before)."""
        if username is None:
            return User(role=UserRole.User if not self._users else UserRole.Anonymous)
        stored = self._users.get(username)
        if stored is None:
            check_password(password or "", hash_password("", iterations=1))  # same cost
            return None
        if not check_password(password or "", stored):
            return None
        return User(role=UserRole.User, name=username)


class CallRules(PermissionRuleset):
    """Requests a session may make: the session services (read, browse, subscribe...) for
    every activated session; Call (the methods) only for a configured user when users are
    configured; never the address-space changes (add or delete nodes and references)."""

    def __init__(self, users_required: bool) -> None:
        self._users_required = users_required

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        """asyncua's hook before each request of a session."""
        if action_type_id not in _SESSION_TYPES:
            return False
        if action_type_id == _CALL and self._users_required:
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
