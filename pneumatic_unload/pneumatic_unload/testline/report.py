# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The quality engineer's report of a results database: one self-contained HTML page.

:func:`html_report` writes a single file (no network, no other file needed to open it):
the parts table with their verdicts, an individuals control chart of C over time per part
type (centre line and 3-sigma limits from the average moving range, points beyond them in
red), the repeatability per part and pooled per part type, the failures with their
reasons, and every unload in a table whose rows open its pressure curve (drawn in the page
from the curve stored with it). C in dm^3/(s bar) on the page (1 dm^3/(s bar) = 1e-8
m^3/(s Pa)); the database keeps SI.
"""

from __future__ import annotations

import datetime as _dt
import html
import json
import math
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pneumatic_unload import __version__
from pneumatic_unload.analysis.output import DM3_PER_S_BAR, c_dm3, two_digits
from pneumatic_unload.estimation.types import ESTIMATE_STATUSES
from pneumatic_unload.testline.batch import part_summary
from pneumatic_unload.testline.db import file_rows, hide_password, open_db, unload_rows

#: d2 of a moving range of two: sigma = average moving range / D2 [-].
D2 = 1.128

_CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}
td,th{border:1px solid #ccc;padding:2px 8px;font-size:13px;text-align:right}
td.l,th.l{text-align:left}
tr.fail td{background:#fde8e8} tr.pass td{background:#eaf7ea}
tr.unload{cursor:pointer} tr.unload:hover td{background:#eef}
#plot{position:fixed;right:1em;top:1em;background:#fff;border:1px solid #888;
padding:0.5em;display:none;box-shadow:2px 2px 8px #888}
h2{margin-top:1.5em}
"""

_JS = """
const DATA = JSON.parse(document.getElementById('curves').textContent);
function showCurve(k) {
  const c = DATA[k], box = document.getElementById('plot');
  if (!c || !c.t.length) { box.innerHTML = '<p>no curve stored for this unload</p>';
    box.style.display = 'block'; return; }
  const W = 420, H = 260, m = 40;
  const t0 = Math.min(...c.t), t1 = Math.max(...c.t);
  const p0 = Math.min(...c.p), p1 = Math.max(...c.p);
  const x = v => m + (W - 2 * m) * (v - t0) / ((t1 - t0) || 1);
  const y = v => H - m - (H - 2 * m) * (v - p0) / ((p1 - p0) || 1);
  const pts = c.t.map((v, i) => x(v).toFixed(1) + ',' + y(c.p[i]).toFixed(1)).join(' ');
  let s = '<svg width="' + W + '" height="' + H + '" id="curve-svg">';
  s += '<polyline fill="none" stroke="#1f77b4" stroke-width="1.5" points="' + pts + '"/>';
  if (c.p_star !== null && c.p_star >= p0 && c.p_star <= p1) {
    s += '<line x1="' + m + '" x2="' + (W - m) + '" y1="' + y(c.p_star) + '" y2="' +
         y(c.p_star) + '" stroke="#d62728" stroke-dasharray="4"/>';
  }
  s += '<text x="' + m + '" y="14" font-size="12">' + c.title + '</text>';
  s += '<text x="' + m + '" y="' + (H - 8) + '" font-size="11">t - t_start [s]: ' +
       t0.toFixed(3) + ' .. ' + t1.toFixed(3) + '</text>';
  s += '<text x="4" y="' + (m - 6) + '" font-size="11">p [kPa] ' + (p0 / 1e3).toFixed(1) +
       ' .. ' + (p1 / 1e3).toFixed(1) + '</text></svg>';
  box.innerHTML = s + '<br><button onclick="this.parentNode.style.display=\\'none\\'">' +
                  'close</button>';
  box.style.display = 'block';
}
document.querySelectorAll('tr.unload').forEach(
  r => r.addEventListener('click', () => showCurve(r.dataset.k)));
const m = location.hash.match(/^#unload=(\\d+)$/);  // a link to one unload's curve
if (m) showCurve(m[1]);
document.body.dataset.ready = String(document.querySelectorAll('tr.unload').length);
"""


def _c(v: Any) -> str:
    """C [m^3/(s Pa)] in dm^3/(s bar) with four significant digits; '-' when unknown."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return c_dm3(v)


def _s(v: Any) -> str:
    """An uncertainty of C [m^3/(s Pa)] in dm^3/(s bar), two significant digits."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return two_digits(v / DM3_PER_S_BAR)


def _e(v: Any) -> str:
    return html.escape("" if v is None else str(v))


#: Half-height of a chart's C axis when its values do not spread it (one unload, or all
#: equal), relative to their centre [-]: 2 % shows a part's C to its fourth digit.
FLAT_HALF_SPAN = 0.02
#: The most part labels under a chart's x axis (more points: every k-th labelled).
MAX_X_LABELS = 30


def nice_ticks(lo: float, hi: float, target: int = 5) -> list[float]:
    """Round tick values (1, 2 or 5 x 10^k apart, about ``target`` of them) within
    [lo, hi]; lo < hi."""
    mag = 10.0 ** math.floor(math.log10((hi - lo) / target))
    step = min((m * mag for m in (1.0, 2.0, 5.0, 10.0)),
               key=lambda st: abs((hi - lo) / st - target))
    first = math.ceil(lo / step - 1e-9) * step
    n = int(math.floor((hi - first) / step + 1e-9)) + 1
    return [first + k * step for k in range(n)]


def _tick_text(v: float, step: float) -> str:
    """A tick value with the decimals its step needs."""
    return f"{v:.{max(0, -math.floor(math.log10(step) + 1e-9))}f}"


def control_chart(points: Sequence[tuple[float, float, str]], title: str) -> str:
    """An individuals control chart as inline SVG: points (x [s or index], C
    [m^3/(s Pa)], label: the part and its input) in order, centre line and centre +- 3
    sigma with sigma = average moving range / :data:`D2` (two points or more; points
    beyond the limits in red); a C axis in dm^3/(s bar) with its values, the points' part
    labels under the x axis. Values that do not spread (one point, all equal) get an axis
    of +- :data:`FLAT_HALF_SPAN` about them and no limits."""
    w, h = 760, 310
    left, right, top, bottom = 78, 20, 44, 80
    if not points:
        return "<p>no C to chart</p>"
    ys = [p[1] / DM3_PER_S_BAR for p in points]
    centre = statistics.fmean(ys)
    mr = [abs(a - b) for a, b in zip(ys[1:], ys[:-1], strict=False)]
    sigma = statistics.fmean(mr) / D2 if mr else 0.0
    limits = sigma > 0
    lo, hi = centre - 3 * sigma, centre + 3 * sigma
    y0, y1 = min(*ys, lo), max(*ys, hi)
    if y1 - y0 <= 1e-12 * max(abs(centre), 1e-300):  # nothing spreads the axis
        half = FLAT_HALF_SPAN * (abs(centre) or 1.0)
        y0, y1 = centre - half, centre + half
    else:
        pad = 0.08 * (y1 - y0)
        y0, y1 = y0 - pad, y1 + pad
    n = len(points)

    def px(i: int) -> float:
        return left + (w - left - right) * ((i + 0.5) / n)

    def py(v: float) -> float:
        return h - bottom - (h - top - bottom) * (v - y0) / (y1 - y0)

    if limits:
        head = (f"centre {_c(centre * DM3_PER_S_BAR)}, limits {_c(lo * DM3_PER_S_BAR)} .. "
                f"{_c(hi * DM3_PER_S_BAR)} (3 sigma, sigma = MR/{D2})")
    elif n == 1:
        head = f"one unload, {_c(centre * DM3_PER_S_BAR)}: no limits (a moving range needs two)"
    else:
        head = f"all {n} equal, {_c(centre * DM3_PER_S_BAR)}: no limits (no moving range)"
    out = [f'<svg width="{w}" height="{h}" class="chart" role="img"><text x="{left}" '
           f'y="16" font-size="13" class="chart-title">{_e(title)}: C [dm^3/(s bar)]</text>'
           f'<text x="{left}" y="32" font-size="11">{_e(head)}</text>']
    # the axes, the C axis's values and its name
    out.append(f'<line class="axis" x1="{left}" x2="{left}" y1="{top}" y2="{h - bottom}" '
               f'stroke="#444"/><line class="axis" x1="{left}" x2="{w - right}" '
               f'y1="{h - bottom}" y2="{h - bottom}" stroke="#444"/>')
    ticks = nice_ticks(y0, y1)
    step = ticks[1] - ticks[0] if len(ticks) > 1 else (y1 - y0)
    for v in ticks:
        out.append(f'<line x1="{left - 4}" x2="{w - right}" y1="{py(v):.1f}" y2="{py(v):.1f}" '
                   f'stroke="#eee"/><text class="y-tick" x="{left - 6}" y="{py(v) + 4:.1f}" '
                   f'font-size="11" text-anchor="end">{_tick_text(v, step)}</text>')
    mid = (top + h - bottom) / 2
    out.append(f'<text class="y-label" x="14" y="{mid:.1f}" font-size="12" '
               f'text-anchor="middle" transform="rotate(-90 14 {mid:.1f})">'
               "C [dm^3/(s bar)]</text>")
    if limits:
        for v, col, dash, name in ((centre, "#444", "", "centre"), (lo, "#d62728", "4", "LCL"),
                                   (hi, "#d62728", "4", "UCL")):
            out.append(f'<line class="limit" x1="{left}" x2="{w - right}" y1="{py(v):.1f}" '
                       f'y2="{py(v):.1f}" stroke="{col}" stroke-dasharray="{dash}"/>'
                       f'<text x="{w - right}" y="{py(v) - 3:.1f}" font-size="10" '
                       f'text-anchor="end" fill="{col}">{name}</text>')
    if n > 1:
        out.append('<polyline fill="none" stroke="#999" points="' + " ".join(
            f"{px(i):.1f},{py(v):.1f}" for i, v in enumerate(ys)) + '"/>')
    every = max(1, math.ceil(n / MAX_X_LABELS))
    for i, (v, p) in enumerate(zip(ys, points, strict=True)):
        col = "#d62728" if (limits and not lo <= v <= hi) else "#1f77b4"
        out.append(f'<circle class="point" cx="{px(i):.1f}" cy="{py(v):.1f}" r="3" '
                   f'fill="{col}"><title>{_e(p[2])}: {_c(v * DM3_PER_S_BAR)} dm^3/(s bar)'
                   "</title></circle>")
        if i % every == 0:
            x, y = px(i), h - bottom + 12
            out.append(f'<text class="x-label" x="{x:.1f}" y="{y}" font-size="10" '
                       f'text-anchor="end" transform="rotate(-40 {x:.1f} {y})">'
                       f"{_e(p[2].split(' ')[0][:18])}</text>")
    out.append(f'<text x="{w - right}" y="{h - 6}" font-size="11" text-anchor="end">'
               f"part of each unload, in time order (n = {n})</text></svg>")
    return "".join(out)


def _directions(part: dict[str, Any]) -> str:
    """Table cells of a part's C by flow direction (weighted mean +- its standard
    uncertainty, dm^3/(s bar)) and the charge's minus the discharge's in their combined
    sigma; '-' where a direction was not measured."""
    d = part.get("by_direction") or {}
    cells = []
    for k in ("discharge", "charge"):
        x = d.get(k)
        cells.append("-" if x is None else f"{_c(x['conductance'])} &plusmn; "
                                           f"{_s(x['std'])} (n {x['n']})")
    if "discharge" in d and "charge" in d:
        a, b = d["discharge"], d["charge"]
        diff = b["conductance"] - a["conductance"]
        z = diff / math.hypot(a["std"], b["std"])
        cells.append(f"{100 * diff / a['conductance']:+.2f} % ({z:+.1f} &sigma;)")
    else:
        cells.append("-")
    return "".join(f"<td>{c}</td>" for c in cells)


def pooled_repeatability(parts: Sequence[dict[str, Any]]) -> float | None:
    """Pooled repeatability standard deviation of parts with n >= 2 [m^3/(s Pa)]:
    sqrt(sum (n_i - 1) s_i^2 / sum (n_i - 1))."""
    num = sum((p["n"] - 1) * p["conductance_std"] ** 2 for p in parts
              if p["n"] >= 2 and p["conductance_std"] is not None)
    den = sum(p["n"] - 1 for p in parts if p["n"] >= 2 and p["conductance_std"] is not None)
    return math.sqrt(num / den) if den > 0 else None


def html_report(db: str | Path, out: str | Path, title: str = "") -> dict[str, int]:
    """Write the report of database ``db`` (a SQLite file or a PostgreSQL URL) to ``out``
    (see the module doc); returns the counts shown (files, unloads, parts, failing parts).

    Raises
    ------
    ResultsDBError
        The database cannot be opened.
    OSError
        ``out`` cannot be written.
    """
    con = open_db(db, create=False)
    try:
        unloads = unload_rows(con)
        files = file_rows(con)
    finally:
        con.close()
    unloads.sort(key=lambda u: (u["t_start"] if u["t_start"] is not None else math.inf,
                                u["path"], u["unload_index"]))
    parts = part_summary(unloads, files)
    failing = [p for p in parts if p["verdict"] == "fail"]
    now = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    h: list[str] = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>{_e(title or 'pneumatic_unload results')}</title><style>{_CSS}</style>"
        "</head><body>",
        f"<h1>{_e(title or 'Test-line results')}</h1>",
        f"<p>Database {_e(hide_password(db))}; {len(files)} input(s), {len(unloads)} unload(s), "
        f"{len(parts)} part(s), {len(failing)} failing; written {now} by pneumatic_unload "
        f"{__version__}. C in dm^3/(s bar) (1 dm^3/(s bar) = 1e-8 m^3/(s Pa)); click an "
        "unload to see its pressure curve.</p>",
        "<h2>Parts</h2>"]
    # a part's C by direction: columns only when some unload of the database is a charge
    two_way = any(u.get("direction") == "charge" for u in unloads)
    if not two_way:
        h.append("<p>Every unload is a discharge (no charge measured): C by direction is "
                 "not shown.</p>")
    h.append("<table id='parts'><tr><th class='l'>part</th><th class='l'>type</th>"
             "<th>n</th><th>C mean</th><th>s(C)</th><th>s/mean</th><th>min</th><th>max</th>"
             + ("<th>C discharge</th><th>C charge</th><th>charge - discharge</th>"
                if two_way else "")
             + "<th class='l'>verdict</th><th class='l'>reason</th></tr>")
    for p in parts:
        rel = (f"{100 * p['conductance_std'] / p['conductance_mean']:.2f} %"
               if p["conductance_std"] is not None and p["conductance_mean"] else "-")
        h.append(f"<tr class='{_e(p['verdict'] or '')}'><td class='l'>{_e(p['part_id'])}</td>"
                 f"<td class='l'>{_e(p['part_type'])}</td><td>{p['n']}</td>"
                 f"<td>{_c(p['conductance_mean'])}</td><td>{_s(p['conductance_std'])}</td>"
                 f"<td>{rel}</td><td>{_c(p['conductance_min'])}</td>"
                 f"<td>{_c(p['conductance_max'])}</td>{_directions(p) if two_way else ''}"
                 f"<td class='l'>{_e(p['verdict'] or '-')}"
                 f"</td><td class='l'>{_e(p['verdict_reason'] or '')}</td></tr>")
    h.append("</table><h2>Control charts of C</h2>")
    types = sorted({u["part_type"] or "" for u in unloads})
    for t in types:
        pts = [(u["t_start"] or 0.0, u["recommended_conductance"], f"{u['part_id']} "
                f"{Path(u['path']).name}#{u['unload_index']}") for u in unloads
               if (u["part_type"] or "") == t and u["recommended_conductance"] is not None
               and u["status"] in ESTIMATE_STATUSES]
        h.append(control_chart(pts, t or "parts without a type"))
    h.append("<h2>Repeatability</h2><table><tr><th class='l'>part type</th><th>parts</th>"
             "<th>pooled s(C)</th></tr>")
    for t in types:
        pool = pooled_repeatability([p for p in parts if (p["part_type"] or "") == t])
        h.append(f"<tr><td class='l'>{_e(t or '-')}</td><td>"
                 f"{sum(1 for p in parts if (p['part_type'] or '') == t)}</td>"
                 f"<td>{_s(pool)}</td></tr>")
    h.append("</table><h2>Failures</h2><ul>")
    bad_files = [f for f in files if f["status"] != "ok"]
    for f in bad_files:
        h.append(f"<li>{_e(f['path'])}: {_e(f['status'])}: {_e(f['reason'])}</li>")
    for u in unloads:
        if u["verdict"] == "fail":
            h.append(f"<li>{_e(u['path'])} unload {u['unload_index']}: "
                     f"{_e(u['verdict_reason'])}</li>")
    if not bad_files and not any(u["verdict"] == "fail" for u in unloads):
        h.append("<li>none</li>")
    h.append("</ul><h2>Unloads</h2><table id='unloads'><tr><th class='l'>part</th>"
             "<th class='l'>input</th><th>#</th><th class='l'>direction</th>"
             "<th class='l'>status</th><th>C</th>"
             "<th>u(C)</th><th>b</th><th>m</th><th>tau_exp [s]</th><th class='l'>heat law</th>"
             "<th class='l'>verdict</th></tr>")
    curves: dict[str, Any] = {}
    for k, u in enumerate(unloads):
        curve = json.loads(u["curve_json"]) if u.get("curve_json") else {"t": [], "p": []}
        p_star = u.get("p_star")
        curves[str(k)] = {**curve, "p_star": p_star,
                          "title": html.escape(f"{u['part_id']} {Path(u['path']).name} "
                                               f"#{u['unload_index']}")}
        b, tau, m = u["critical_ratio"], u["tau_exp"], u.get("subsonic_index")
        h.append(f"<tr class='unload {_e(u['verdict'] or '')}' data-k='{k}'>"
                 f"<td class='l'>{_e(u['part_id'])}</td><td class='l'>"
                 f"{_e(Path(u['path']).name)}</td><td>{u['unload_index']}</td>"
                 f"<td class='l'>{_e(u.get('direction') or 'discharge')}</td>"
                 f"<td class='l'>{_e(u['status'])}</td>"
                 f"<td>{_c(u['recommended_conductance'])}</td>"
                 f"<td>{_s(u['recommended_std'])}</td>"
                 f"<td>{'-' if b is None else f'{b:.3f}'}</td>"
                 f"<td>{'-' if m is None else f'{m:.2f}'}</td>"
                 f"<td>{'-' if tau is None else f'{tau:.4f}'}</td>"
                 f"<td class='l'>{_e(u['heat_law'])}</td>"
                 f"<td class='l'>{_e(u['verdict'] or '-')}</td></tr>")
    data = json.dumps(curves).replace("</", "<\\/")
    h.append(f"</table><div id='plot'></div><script type='application/json' id='curves'>"
             f"{data}</script><script>{_JS}</script></body></html>")
    Path(out).write_text("".join(h), encoding="utf-8")
    return {"files": len(files), "unloads": len(unloads), "parts": len(parts),
            "failing_parts": len(failing)}
