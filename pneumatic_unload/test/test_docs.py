# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The documentation site: it builds with warnings as errors, a headless Chromium opens its
index, no internal link is broken, and it names every CLI command and option, every node and
every node parameter, and every key of ``analyze --json``; the hand-written pages are in it; the
README is short and its relative links resolve."""

import argparse
import contextlib
import dataclasses
import io
import json
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from pneumatic_unload.analysis import output
from pneumatic_unload.app.cli import build_parser, main
from pneumatic_unload.config import nodes
from pneumatic_unload.estimation import UnloadResult

REPO = Path(__file__).resolve().parents[2]  # the repository (docs/, README.md)
BUILD_TIMEOUT_S = 300
README_MAX_LINES = 150
#: the hand-written pages (issue #28): tutorials, how-to guides, explanation
HAND_PAGES = (
    "tutorials/index", "tutorials/first_measurement", "tutorials/live_bench",
    "tutorials/test_line",
    "howto/index", "howto/analyze", "howto/logger_files", "howto/transducers", "howto/start_time",
    "howto/temperature", "howto/charge", "howto/discrepancy", "howto/cell",
    "explanation/index", "explanation/method", "explanation/budget",
    "explanation/validation", "explanation/architecture",
)


class _Page(HTMLParser):
    """The ids, internal links and text (whole and per ``<section id>``) of one HTML page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.hrefs: list[str] = []
        self.text: list[str] = []
        self.sections: dict[str, list[str]] = {}
        self._open: list[str | None] = []  # the id of each open <section> (None: no id)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        for key in ("id", "name"):
            if a.get(key):
                self.ids.add(str(a[key]))
        if tag == "a" and a.get("href") is not None:
            self.hrefs.append(str(a["href"]))
        if tag == "section":
            self._open.append(a.get("id"))
            if a.get("id"):
                self.sections[str(a["id"])] = []

    def handle_endtag(self, tag: str) -> None:
        if tag == "section" and self._open:
            self._open.pop()

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        for sid in self._open:
            if sid:
                self.sections[sid].append(data)


def _parse(html: str) -> _Page:
    page = _Page()
    page.feed(html)
    return page


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built from this checkout's docs/ with warnings as errors (``make docs``)."""
    out = tmp_path_factory.mktemp("docs") / "html"
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         "-d", str(out.parent / "doctrees"), str(REPO / "docs"), str(out)],
        capture_output=True, text=True, timeout=BUILD_TIMEOUT_S, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert proc.stderr.strip() == "", proc.stderr[-4000:]
    return out


@pytest.fixture(scope="module")
def pages(site: Path) -> dict[Path, _Page]:
    return {p: _parse(p.read_text(encoding="utf-8")) for p in sorted(site.rglob("*.html"))}


def _broken_links(site: Path, page: Path, parsed: _Page, pages: dict[Path, _Page]
                  ) -> list[str]:
    """The internal links of ``page`` whose file or anchor does not exist."""
    bad = []
    for href in parsed.hrefs:
        parts = urlsplit(href)
        if parts.scheme or parts.netloc:  # http(s), mailto: not internal
            continue
        target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
        if target.is_dir():
            target = target / "index.html"
        if not target.is_file() or site.resolve() not in target.parents:
            bad.append(f"{page.relative_to(site)}: {href} (no file)")
            continue
        anchor = unquote(parts.fragment)
        if anchor and target.suffix == ".html":
            ids = pages[target].ids if target in pages else _parse(target.read_text()).ids
            if anchor not in ids:
                bad.append(f"{page.relative_to(site)}: {href} (no id {anchor!r})")
    return bad


def test_chromium_opens_the_index_and_no_internal_link_is_broken(site, pages, tmp_path):
    index = site / "index.html"
    resolved = {p.resolve(): v for p, v in pages.items()}
    bad = [b for p, parsed in pages.items()
           for b in _broken_links(site.resolve(), p.resolve(), parsed, resolved)]
    assert bad == []
    # every page is reached from the index through the site's links
    seen, todo = set(), [index.resolve()]
    while todo:
        page = todo.pop()
        if page in seen or page.suffix != ".html":
            continue
        seen.add(page)
        for href in resolved[page].hrefs:
            parts = urlsplit(href)
            if not parts.scheme and not parts.netloc and parts.path:
                todo.append((page.parent / unquote(parts.path)).resolve())
    unreached = sorted(str(p.relative_to(site.resolve())) for p in set(resolved) - seen)
    assert unreached == []

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("no chromium (CI installs Debian's chromium; apt install chromium)")
    r = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                        "--enable-logging=stderr", "--v=0",
                        f"--user-data-dir={tmp_path / 'chromium'}", "--dump-dom",
                        index.as_uri()], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    dom = _parse(r.stdout)
    assert "Command line: pneumatic-unload" in "".join(dom.text)
    assert _broken_links(site.resolve(), index.resolve(), dom, resolved) == []
    links = {urlsplit(h).path for h in dom.hrefs}
    for name in ("cli", "nodes", "interfaces", "json", "api", "architecture"):
        assert f"_generated/{name}.html" in links, name
    errors = [ln for ln in r.stderr.splitlines() if "Uncaught" in ln
              or ("CONSOLE" in ln and "error" in ln.lower())]
    assert errors == [], errors


def _commands() -> dict[str, argparse.ArgumentParser]:
    out = {}

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    out[prefix + name] = sub
                    walk(sub, f"{prefix}{name} ")

    walk(build_parser(), "")
    return out


def test_site_names_every_cli_command_and_option(pages, site):
    page = pages[site / "_generated" / "cli.html"]
    commands = _commands()
    assert {"analyze", "simulate", "recover", "discrepancy", "batch", "results",
            "report"} <= set(commands)
    for name, parser in commands.items():
        section = "".join(page.sections[f"pneumatic-unload-{name.replace(' ', '-')}"])
        assert f"pneumatic-unload {name}" in section
        for action in parser._actions:
            shown = parser._get_formatter()._format_action_invocation(action)
            for opt in action.option_strings or [shown]:
                assert opt in section, (name, opt)
            if action.help and action.option_strings and action.help != argparse.SUPPRESS:
                shown = parser._get_formatter()._expand_help(action)  # as --help prints it
                assert " ".join(shown.split()) in " ".join(section.split()), \
                    (name, action.option_strings)


def test_site_names_every_node_and_parameter(pages, site):
    page = pages[site / "_generated" / "nodes.html"]
    assert set(nodes.NODES) == {"estimator", "simulator", "recorder", "replay", "opcua"}
    for node in nodes.NODES:
        section = page.sections[node]
        words = set(" ".join(section).split())
        params = nodes.node_parameters(node)
        assert params
        missing = [p for p in params if p not in words]
        assert missing == [], (node, missing)


def test_site_documents_every_key_of_analyze_json(pages, site, tmp_path, monkeypatch):
    """The keys of a real ``analyze --json`` (a simulated bag) are those the JSON page
    lists (from output.py and UnloadResult's documented fields)."""
    bag = tmp_path / "run"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "--out", str(bag), "--volume", "0.001", "--seed", "3"]) == 0
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["analyze", str(bag), "--json"]) == 0
    doc = json.loads(buf.getvalue())
    assert set(doc) == set(output.ANALYZE_JSON_KEYS)
    fields = {f.name for f in dataclasses.fields(UnloadResult)} - set(output.UNLOAD_JSON_DROPPED)
    documented = fields | set(output.UNLOAD_JSON_KEYS)
    results = doc["unloads"] + doc["published"]
    assert any(r["final"] for r in results) and any(not r["final"] for r in results)
    for r in results:
        assert set(r) <= documented, set(r) - documented
    words = set("".join(pages[site / "_generated" / "json.html"].text).split())
    assert documented | set(doc) <= words, (documented | set(doc)) - words
    # every field of the result carries its meaning (a #: comment) on the page
    monkeypatch.syspath_prepend(str(REPO / "docs" / "_ext"))
    from generated_reference import unload_fields

    assert [n for n, _, meaning in unload_fields() if not meaning] == []


def test_readme_is_short_and_its_relative_links_resolve():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= README_MAX_LINES
    # [text](target) and ![alt](target): every target that is not a URL or an anchor
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    assert targets
    relative = [t for t in targets if not urlsplit(t).scheme and not t.startswith("#")]
    missing = [t for t in relative if not (REPO / unquote(urlsplit(t).path)).exists()]
    assert missing == []
    # the hand pages the README links to are the site's
    for page in HAND_PAGES:
        if not page.endswith("index"):
            assert f"docs/{page}.rst" in relative, page


def test_site_has_the_hand_pages_reached_from_the_index(pages, site):
    index = pages[site / "index.html"]
    links = {urlsplit(h).path for h in index.hrefs}
    for page in HAND_PAGES:
        assert (site / f"{page}.html").is_file(), page
        assert (REPO / "docs" / f"{page}.rst").is_file(), page
    for part in ("tutorials", "howto", "explanation"):
        assert f"{part}/index.html" in links, part
    # the README's picture is on the first tutorial
    assert any(p.name == "measurement.png" for p in (site / "_images").iterdir())
