# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The documentation reads like a product's, not like a development log: no "session N",
no commit hashes, no issue numbers, no test-case names or draw numbers in the pages a user
follows; long commands wrap (docs/_static/wrap.css). A grep of the sources: fast, no build."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"

#: Development-log wording, refused on every hand-written page and in the README: the
#: pattern and what it is.
HISTORY_WORDS: tuple[tuple[str, str], ...] = (
    (r"\bsessions?\s+\d+", "a session number"),
    (r"\b(?:this|that|last|previous|next|same|earlier|later)\s+session\b", "a session"),
    (r"\b(?:main|commit|code of)\s+[0-9a-f]{7,40}\b", "a commit"),
    (r"(?<![\w./#-])(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,12}(?![\w/-])", "a commit hash"),
    (r"\bissues?\s+#?\d+", "an issue number"),
    (r"\(#\d+\)|\bPR\s*#?\d+", "an issue number"),
    (r"\bwas stale\b|\bunchanged by this\b|\bfixed in\b", "a change log"),
)
#: Names of the test harnesses' cases and numbered random draws: fine in the validation
#: page (its figures), refused on the pages a user follows (tutorials, how-tos, the other
#: explanations, the README).
CASE_WORDS: tuple[tuple[str, str], ...] = (
    (r"\bc\d{2}-[a-z]+\d*\b", "a test case's name"),
    (r"\bdraws?\s+#?\d+", "a draw number"),
)
#: The page that reports the validation figures (case names and draw numbers allowed).
FIGURES_PAGE = DOCS / "explanation" / "validation.rst"


def _pages() -> list[Path]:
    hand = [p for p in sorted(DOCS.rglob("*.rst"))
            if "_build" not in p.parts and "_generated" not in p.parts]
    assert len(hand) >= 15, hand
    return [*hand, REPO / "README.md"]


def _hits(text: str, rules: tuple[tuple[str, str], ...]) -> list[str]:
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        for pattern, what in rules:
            for m in re.finditer(pattern, line, flags=re.IGNORECASE):
                out.append(f"{n}: {what}: {m.group(0)!r} in {line.strip()[:100]!r}")
    return out


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(REPO)))
def test_page_has_no_development_log_wording(page: Path):
    rules = HISTORY_WORDS if page == FIGURES_PAGE else HISTORY_WORDS + CASE_WORDS
    hits = _hits(page.read_text(encoding="utf-8"), rules)
    assert hits == [], "\n".join(hits)


@pytest.mark.parametrize("line, caught", [
    ("(session 29; they gave 2-6)", True), ("on session 33's machine", True),
    ("main d03e495, 55 unloads", True), ("Then (1ed46a7) a hot start", True),
    ("before issue #24", True), ("the test line (#14)", True), ("c07-hot5: +1.7 %", True),
    ("Foreign draw 200 (two", True), ("the session stays alive", False),
    ("1 dm^3/(s bar) = 1e-8 m^3/(s Pa)", False), ("p99 0.795-0.938 ms", False),
    ("``--seed 1234567``", False), ("random draws of the grid", False),
])
def test_the_rules_catch_what_they_are_for(line: str, caught: bool):
    assert bool(_hits(line, HISTORY_WORDS + CASE_WORDS)) is caught, line


def test_long_commands_wrap():
    """A long command in a literal block or inline literal wraps (it was cut behind a
    scroll bar): the site's style sheet says pre-wrap for both, and conf.py loads it."""
    css = (DOCS / "_static" / "wrap.css").read_text()
    for selector in ("pre", "code"):
        block = re.search(rf"(^|[,}}\s]){selector}\b[^{{]*\{{([^}}]*)\}}", css, re.MULTILINE)
        assert block is not None and "white-space: pre-wrap" in block.group(2), selector
    conf = (DOCS / "conf.py").read_text()
    assert re.search(r'html_css_files\s*=\s*\[[^]]*"wrap\.css"', conf)
    assert re.search(r'html_static_path\s*=\s*\[[^]]*"_static"', conf)


def test_method_page_states_the_iso_linear_branch_as_the_package_computes_it():
    """ISO 6358-1:2013's linear branch above r = 0.999 (a charge's last 700 Pa) was in no
    user page: the method page gives it, and its formula is the one flow_function uses."""
    from pneumatic_unload.physics import R_LINEAR, flow_function

    page = (DOCS / "explanation" / "method.rst").read_text()
    assert "phi = phi_l (1 - r) / (1 - r_l)" in page
    assert "phi_l = [1 - ((r_l - b)/(1 - b))^q]^m" in page
    assert f"r_l = {R_LINEAR}" in page and "700 Pa" in page
    for b, m in ((0.5, 0.5), (0.3, 0.4), (0.45, 0.62)):
        phi_l = (1.0 - ((R_LINEAR - b) / (1.0 - b)) ** 2) ** m
        for r in (0.9991, 0.9995, 0.99999, 1.0, 1.0002):
            assert float(flow_function(r, b, m)) == pytest.approx(
                phi_l * (1.0 - r) / (1.0 - R_LINEAR), rel=1e-12, abs=1e-15), (b, m, r)
    # the page's example: phi_l 0.063 (b 0.5, m 0.5); tau_l = V (1 - r_l) / (p_N C phi_l)
    phi_l = float(flow_function(R_LINEAR, 0.5, 0.5))
    assert "phi_l = 0.063 for b = 0.5, m = 0.5" in page and round(phi_l, 3) == 0.063
    assert "tau_l = 0.03 s" in page
    assert round(1e-3 * (1.0 - R_LINEAR) / (1e5 * 5e-9 * phi_l), 2) == 0.03
