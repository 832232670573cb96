# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Specifications of part types: the ranges a measured C and b must lie in to pass.

A specification is a YAML (or JSON) file::

    # C in m^3/(s Pa) (1 dm^3/(s bar) = 1e-8 m^3/(s Pa)); b [-]
    part_types:
      valve-g14:
        match: "^V14-"                 # regular expression on the part id
        conductance: [4.5e-9, 5.5e-9]  # C range (the recommended C of each unload)
        critical_ratio: [0.3, 0.6]     # b range (optional)
        max_relative_std: 0.02         # sigma(C)/C at most (optional)

    # optional: settings for some inputs [SI], by a regular expression on the input's path;
    # they win over what a bag records (the command line's do not, without --override)
    files:
      "V14-007":
        volume: 4.0e-3

The first part type whose ``match`` finds the part id applies; a part with none has no
verdict. The first ``files`` entry whose expression finds the path applies. An unload
passes when its recommended C (and b, and sigma(C)/C, when the type states them) lie in
range; an unload without a C fails with its reason; a part passes when every unload does.
SI units.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneumatic_unload.analysis.output import DM3_PER_S_BAR, finite_or_none
from pneumatic_unload.estimation.types import ESTIMATE_STATUSES


class SpecError(Exception):
    """A specification file that cannot be used (a one-line message naming the file)."""


@dataclass(frozen=True)
class PartType:
    """One part type's limits (SI; NaN: no limit).

    Attributes
    ----------
    name : str
        The part type.
    match : str
        Regular expression on the part id.
    c_min, c_max : float
        C range [m^3/(s Pa)].
    b_min, b_max : float
        b range [-].
    max_relative_std : float
        Largest sigma(C)/C [-].
    """

    name: str
    match: str
    c_min: float
    c_max: float
    b_min: float = math.nan
    b_max: float = math.nan
    max_relative_std: float = math.nan

    def judge(self, u: dict[str, Any]) -> tuple[str, str]:
        """('pass' | 'fail', reason) of one unload given as its result's JSON."""
        c = u.get("recommended_conductance")
        sd = u.get("recommended_std")
        if u.get("status") not in ESTIMATE_STATUSES or c is None:
            return "fail", f"no C: {u.get('status')}: {u.get('status_text')}"
        why = []
        if not self.c_min <= c <= self.c_max:
            why.append(f"C {c / DM3_PER_S_BAR:.4g} dm^3/(s bar) outside "
                       f"[{self.c_min / DM3_PER_S_BAR:.4g}, {self.c_max / DM3_PER_S_BAR:.4g}]")
        if math.isfinite(self.b_min) or math.isfinite(self.b_max):
            b = u.get("critical_ratio")
            if b is None:
                why.append("b not determined (no subsonic tail fitted): cannot check "
                           f"[{self.b_min:g}, {self.b_max:g}]")
            elif not self.b_min <= b <= self.b_max:
                why.append(f"b {b:.3f} outside [{self.b_min:g}, {self.b_max:g}]")
        if math.isfinite(self.max_relative_std):
            rel = sd / c if sd is not None and c > 0 else math.inf
            if not rel <= self.max_relative_std:
                why.append(f"sigma(C)/C {100 * rel:.2f} % above "
                           f"{100 * self.max_relative_std:.2f} %")
        return ("fail", "; ".join(why)) if why else ("pass", "within specification")


@dataclass(frozen=True)
class Spec:
    """The part types of a specification file, in file order."""

    types: tuple[PartType, ...]
    #: (regular expression on an input's path, estimator settings [SI]), in file order
    files: tuple[tuple[str, dict[str, Any]], ...] = ()

    def file_settings(self, path: str) -> dict[str, Any]:
        """The settings of the first ``files`` entry whose expression finds ``path``."""
        return next((dict(d) for rx, d in self.files if re.search(rx, path)), {})

    def part_type(self, part_id: str) -> str:
        """The name of the first part type matching ``part_id`` ('' when none)."""
        t = self._type(part_id)
        return t.name if t is not None else ""

    def _type(self, part_id: str) -> PartType | None:
        return next((t for t in self.types if re.search(t.match, part_id)), None)

    def judge(self, part_id: str, u: dict[str, Any]) -> tuple[str, str] | None:
        """('pass' | 'fail', reason) of an unload of ``part_id``; None without a type."""
        t = self._type(part_id)
        return t.judge(u) if t is not None else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN limits as None)."""
        out: dict[str, Any] = {"part_types": [finite_or_none(vars(t)) for t in self.types]}
        if self.files:
            out["files"] = [[rx, d] for rx, d in self.files]
        return out


def _pair(name: str, key: str, v: Any, src: str) -> tuple[float, float]:
    if v is None:
        return math.nan, math.nan
    if not (isinstance(v, (list, tuple)) and len(v) == 2
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise SpecError(f"{src}: part type {name!r}: {key} must be [min, max], got {v!r}")
    lo, hi = float(v[0]), float(v[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise SpecError(f"{src}: part type {name!r}: {key} [{lo:g}, {hi:g}] is not a range")
    return lo, hi


def parse_spec(data: Any, src: str = "specification") -> Spec:
    """A :class:`Spec` from the mapping of a specification file (see the module doc).

    Raises
    ------
    SpecError
        Missing or malformed entries, a bad regular expression, C outside
        [1e-13, 1e-5] m^3/(s Pa) (a value in dm^3/(s bar) given as SI?).
    """
    if not isinstance(data, dict) or not isinstance(data.get("part_types"), dict) \
            or not data["part_types"]:
        raise SpecError(f"{src}: expected a mapping 'part_types' of part type names")
    unknown_top = set(data) - {"part_types", "files"}
    if unknown_top:
        raise SpecError(f"{src}: unknown keys {sorted(unknown_top)} (part_types, files)")
    files = _file_settings(data.get("files"), src)
    out = []
    for name, d in data["part_types"].items():
        if not isinstance(d, dict):
            raise SpecError(f"{src}: part type {name!r} must be a mapping")
        unknown = set(d) - {"match", "conductance", "critical_ratio", "max_relative_std"}
        if unknown:
            raise SpecError(f"{src}: part type {name!r}: unknown keys {sorted(unknown)}")
        match = d.get("match", f"^{re.escape(str(name))}")
        try:
            re.compile(match)
        except re.error as exc:
            raise SpecError(f"{src}: part type {name!r}: bad match {match!r}: {exc}"
                            ) from exc
        if "conductance" not in d:
            raise SpecError(f"{src}: part type {name!r}: conductance [min, max] "
                            "[m^3/(s Pa)] is required")
        c_lo, c_hi = _pair(str(name), "conductance", d["conductance"], src)
        if not (1e-13 <= c_lo and c_hi <= 1e-5):
            raise SpecError(
                f"{src}: part type {name!r}: conductance [{c_lo:g}, {c_hi:g}] is not in "
                "m^3/(s Pa) (1 dm^3/(s bar) = 1e-8 m^3/(s Pa))")
        b_lo, b_hi = _pair(str(name), "critical_ratio", d.get("critical_ratio"), src)
        rel = d.get("max_relative_std")
        if rel is not None and not (isinstance(rel, (int, float)) and 0 < rel < 1):
            raise SpecError(f"{src}: part type {name!r}: max_relative_std must be in (0, 1)")
        out.append(PartType(str(name), match, c_lo, c_hi, b_lo, b_hi,
                            float(rel) if rel is not None else math.nan))
    return Spec(tuple(out), files)


def _file_settings(data: Any, src: str) -> tuple[tuple[str, dict[str, Any]], ...]:
    """The ``files`` entries of a specification: (expression, settings [SI])."""
    if data is None:
        return ()
    if not isinstance(data, dict):
        raise SpecError(f"{src}: files must be a mapping of path expressions to settings")
    from pneumatic_unload.config import ConfigError, adapters
    from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings

    out = []
    for rx, d in data.items():
        try:
            re.compile(str(rx))
        except re.error as exc:
            raise SpecError(f"{src}: files: bad expression {rx!r}: {exc}") from exc
        if not isinstance(d, dict):
            raise SpecError(f"{src}: files: {rx!r} must be a mapping of estimator settings")
        try:
            settings = adapters.from_mapping(EstimatorSettings, d)
            EstimatorSettings(**{"volume": 1e-3, **settings})  # each value in range
        except (ConfigError, EstimationError, TypeError) as exc:
            raise SpecError(f"{src}: files: {rx!r}: {exc}") from exc
        out.append((str(rx), settings))
    return tuple(out)


def read_file_data(path: str | Path) -> Any:
    """The data of a YAML or JSON file (JSON by the .json suffix, else YAML).

    Raises
    ------
    SpecError
        Unreadable file or invalid YAML/JSON (a one-line message naming the file).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise SpecError(f"{p}: {exc}") from exc
    try:
        if p.suffix.lower() == ".json":
            return json.loads(text)
        import yaml

        return yaml.safe_load(text)
    except Exception as exc:  # any parser's error: the file is not YAML/JSON
        raise SpecError(f"{p}: not valid {p.suffix.lstrip('.') or 'YAML'}: {exc}") from exc


def load_spec(path: str | Path) -> Spec:
    """Read a specification file (YAML or JSON).

    Raises
    ------
    SpecError
        Unreadable or malformed file.
    """
    return parse_spec(read_file_data(path), str(path))
