# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A database URL's password kept out of every message, whatever the URL's form.

:func:`redact` is the one function every message of the results database goes through
(:func:`~.schema.hide_password` for the URL shown, :class:`~.db.ResultsDB` and
:func:`~.db.open_db` for the errors). It does not trust one parser's reading of the URL:
it masks the password read up to the last ``@`` of the authority (a raw ``@`` inside the
password: SQLAlchemy stops at the first one and takes the rest for the start of the host
name, which a driver's message then repeats) and the values of ``password=`` query
parameters (any case), each percent-decoded as well; the pieces of a password split at a
raw ``@`` are masked where an ``@`` follows them.
"""

from __future__ import annotations

import re
import urllib.parse
from pathlib import Path

__all__ = ["MASK", "redact", "secrets_of"]

#: What a password is replaced with.
MASK = "***"

_QUERY_PASSWORD = re.compile(r"(?i)(?:^|[?&;])password=([^&;#]*)")


def _userinfo_password(target: str) -> str:
    """The password of ``user:PASSWORD@host`` read up to the last ``@`` ('' if none)."""
    if "://" not in target:
        return ""
    authority = target.split("://", 1)[1].partition("?")[0]
    if "@" not in authority:
        return ""
    userinfo = authority.rsplit("@", 1)[0]
    return userinfo.split(":", 1)[1] if ":" in userinfo else ""


def secrets_of(target: str | Path) -> tuple[str, ...]:
    """Every string of ``target`` (a database URL) that is its password in some reading,
    longest first (a plain path: none)."""
    s = str(target)
    if "://" not in s:
        return ()
    found = {_userinfo_password(s)}
    found.update(m.group(1) for m in _QUERY_PASSWORD.finditer(s.split("://", 1)[1]))
    more = {urllib.parse.unquote(x) for x in found} | {urllib.parse.unquote_plus(x)
                                                       for x in found}
    return tuple(sorted((x for x in found | more if x), key=len, reverse=True))


def _pieces(target: str | Path) -> tuple[str, ...]:
    """The pieces of a password with a raw ``@``: before and after each ``@``."""
    password = _userinfo_password(str(target))
    out = set()
    for i, ch in enumerate(password):
        if ch == "@":
            out.update(x for x in (password[:i], password[i + 1:]) if x)
    return tuple(sorted(out, key=len, reverse=True))


def redact(text: str, target: str | Path) -> str:
    """``text`` with every reading of ``target``'s password (see :func:`secrets_of`)
    replaced by :data:`MASK`, and the pieces of a password with a raw ``@`` where an
    ``@`` follows them (the host name a parser stopping at the first ``@`` reads)."""
    for secret in secrets_of(target):
        text = text.replace(secret, MASK)
    for piece in _pieces(target):
        text = re.sub(re.escape(piece) + "(?=@)", MASK, text)
    return text
