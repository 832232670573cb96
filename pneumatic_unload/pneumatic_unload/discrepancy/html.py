# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""One self-contained HTML page from the discrepancy report's Markdown.

The page is the same text as ``report.md`` (so the two never disagree), rendered from the
small Markdown subset the report uses: headings, paragraphs, bullet lists, pipe tables,
``**bold**``, ``code`` and images on a line of their own. Images are read from the report's
folder and embedded as base64 ``data:`` URIs, and the style sheet is inline: the page opens
offline, can be mailed as one file, and references nothing outside itself.
"""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path

_IMAGE = re.compile(r"^!\[([^\]]*)\]\(([^)\s]+)\)$")
_BOLD = re.compile(r"\*\*(.+?)\*\*")
_CODE = re.compile(r"`([^`]+)`")
_MIME = {".png": "image/png", ".svg": "image/svg+xml"}

STYLE = """
body { font-family: system-ui, sans-serif; max-width: 62em; margin: 2em auto;
       padding: 0 1em; line-height: 1.45; color: #222; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { border-bottom: 1px solid #bbb; margin-top: 1.8em; }
table { border-collapse: collapse; margin: .8em 0; }
th, td { border: 1px solid #bbb; padding: .25em .6em; text-align: left; }
th { background: #eee; }
img { max-width: 100%; height: auto; display: block; margin: .8em 0; }
code { background: #f3f3f3; padding: 0 .2em; }
"""


def _inline(text: str) -> str:
    """Escaped text with **bold** and `code` rendered."""
    out = html.escape(text, quote=False)
    out = _BOLD.sub(r"<strong>\1</strong>", out)
    return _CODE.sub(r"<code>\1</code>", out)


def _image(alt: str, name: str, folder: Path) -> str:
    """An <img> with the file's bytes inline (a note instead when it cannot be read)."""
    path = folder / name
    mime = _MIME.get(path.suffix.lower())
    try:
        data = path.read_bytes() if mime else b""
    except OSError:
        data = b""
    if not data:
        return f"<p><em>[plot {html.escape(name)} not available]</em></p>"
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:{mime};base64,{b64}">'


def _table(rows: list[str]) -> str:
    cells = [[c.strip() for c in r.strip().strip("|").split("|")] for r in rows]
    head, body = cells[0], [c for c in cells[1:] if not all(re.fullmatch(r":?-+:?", x)
                                                              for x in c)]
    out = ["<table>", "<tr>" + "".join(f"<th>{_inline(c)}</th>" for c in head) + "</tr>"]
    out += ["<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in body]
    return "\n".join([*out, "</table>"])


def markdown_to_html(text: str, folder: Path, title: str) -> str:
    """The HTML page of the report's Markdown ``text``; images are read from ``folder``.

    Parameters
    ----------
    text : str
        Markdown of :func:`pneumatic_unload.discrepancy.report.markdown`.
    folder : Path
        Folder holding the images the Markdown names.
    title : str
        Page title.
    """
    out: list[str] = []
    para: list[str] = []
    items: list[str] = []
    table: list[str] = []

    def flush() -> None:
        if para:
            out.append("<p>" + _inline(" ".join(para)) + "</p>")
            para.clear()
        if items:
            out.append("<ul>\n" + "\n".join(f"<li>{_inline(i)}</li>" for i in items)
                       + "\n</ul>")
            items.clear()
        if table:
            out.append(_table(table))
            table.clear()

    for raw in text.splitlines():
        line = raw.rstrip()
        m = _IMAGE.match(line.strip())
        if not line.strip():
            flush()
        elif line.startswith("#"):
            flush()
            level = min(len(line) - len(line.lstrip("#")), 6)
            out.append(f"<h{level}>{_inline(line[level:].strip())}</h{level}>")
        elif m:
            flush()
            out.append(_image(m.group(1), m.group(2), folder))
        elif line.lstrip().startswith("|"):
            if para or items:
                flush()
            table.append(line)
        elif line.startswith("- "):
            if para or table:
                flush()
            items.append(line[2:])
        elif items and line.startswith("  "):
            items[-1] += " " + line.strip()
        else:
            if items or table:
                flush()
            para.append(line.strip())
    flush()
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{html.escape(title)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
            + "\n".join(out) + "\n</body>\n</html>\n")
