# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Property-based fuzzing of the readers, the command line and the discrepancy workflow
(issue #13): CSV files, bags written by the package's writer (some damaged), ``pneumatic-unload
analyze`` in-process, and small discrepancy cases. Builds on :mod:`fuzzcases` (the analysis
properties and the wild discharges); shared by ``test/test_fuzz.py`` and
``bench/bench_fuzz.py``. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from fuzzcases import (
    JUNK,
    P_ATM,
    FuzzFailure,
    clean_discharge,
    run_analyze,
    wild_discharges,
)
from hypothesis import strategies as st

from pneumatic_unload.config import EFFECTS
from pneumatic_unload.estimation import EstimatorSettings


# ------------------------------------------------------------------------------- CLI glue
def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``pneumatic-unload ARGV`` in-process: (exit status, stdout, stderr). Exit statuses
    0, 1 and 2 are answers; a traceback is a failure (raised as is)."""
    from pneumatic_unload.app.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse: bad options
            rc = int(exc.code or 0)
    if rc not in (0, 1, 2):
        raise FuzzFailure(f"exit status {rc}: {err.getvalue()[-300:]}")
    return rc, out.getvalue(), err.getvalue()


def check_cli_json(rc: int, out: str, err: str) -> None:
    """``analyze --json`` output: every 'ok' unload has finite, positive C and tau_exp; exit
    1 says why on stderr."""
    if rc == 2:
        if not err.strip():
            raise FuzzFailure("exit 2 without a message")
        return
    doc = json.loads(out)
    for u in doc["unloads"] + doc["published"]:
        if u["status"] == "ok":
            for k in ("conductance", "tau_exp"):
                if not (isinstance(u[k], float) and u[k] > 0):
                    raise FuzzFailure(f"CLI: status ok with {k}={u[k]!r}")
    if rc == 1 and not err.strip():
        raise FuzzFailure("exit 1 without a reason on stderr")


def write_csv_text(path: Path, text: str | bytes) -> Path:
    """Write CSV text (or raw bytes) to ``path``."""
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------------------ CSV files
CSV_TIME_HEADERS = ("time", "Time [s]", "t", "Time [ms]", "time (min)", "Zeit", "time [h]",
                    "Time [parsec]", "")
CSV_PRESSURE_HEADERS = ("pressure", "Pressure [Pa]", "Pressure [kPa]", "p [bar g]",
                        "Pressure [psig]", "P [bar(a)]", "pressure [mbar]", "Druck",
                        "Pressure [furlong]", "p", "pressure [kPa abs]", "")
CSV_TEMP_HEADERS = (None, "Temp [C]", "temperature [K]", "temp [F]")
CSV_SCALE = {"ms": 1e3, "min": 1 / 60, "h": 1 / 3600, "kPa": 1e-3, "bar": 1e-5, "psi":
             1 / 6894.757293168361, "mbar": 1e-2}


def _unit_scale(header: str) -> float:
    """Factor from SI to the unit named in ``header`` (1 when unknown)."""
    for unit, k in CSV_SCALE.items():
        if f"[{unit}" in header or f"({unit}" in header:
            return k
    return 1.0


@st.composite
def csv_files(draw: st.DrawFn, *, max_samples: int = 3000) -> tuple[str | bytes,
                                                                   dict[str, Any]]:
    """CSV text of a (corrupted) discharge with a drawn header, units, delimiter and cell
    format, some rows or cells broken; and the reader options (keyword arguments of
    :func:`~pneumatic_unload.io.csvlog.read_csv_trace`)."""
    if draw(st.integers(0, 9)) == 0:  # pure garbage
        return draw(st.one_of(st.binary(max_size=400), st.text(max_size=400))), {}
    t, p, cfg = draw(wild_discharges(max_samples=max_samples))
    clean = draw(st.integers(0, 3)) > 0  # mostly a well-formed file: reaches the estimator
    if clean:
        th, ph = draw(st.sampled_from(CSV_TIME_HEADERS[:4])), draw(st.sampled_from(
            CSV_PRESSURE_HEADERS[:7]))
        temp_h = draw(st.sampled_from(CSV_TEMP_HEADERS[:3]))
    else:
        th = draw(st.sampled_from(CSV_TIME_HEADERS))
        ph = draw(st.sampled_from(CSV_PRESSURE_HEADERS))
        temp_h = draw(st.sampled_from(CSV_TEMP_HEADERS))
    gauge_hdr = " g]" in ph or "psig" in ph
    p_out = (p - P_ATM if gauge_hdr else p) * _unit_scale(ph)
    t_out = t * _unit_scale(th)
    delim = draw(st.sampled_from([",", ";", "\t"] if clean else [",", ";", "\t", " "]))
    fmt = draw(st.sampled_from(["{!r}", "{:.9g}"] if clean else
                               ["{!r}", "{:.3f}", "{:.6g}", "{:.0f}", "{:.2e}"]))
    decimal_comma = not clean and draw(st.integers(0, 3)) == 0
    header = [th, ph] + ([temp_h] if temp_h else [])
    if draw(st.booleans()):
        header = header[::-1] if draw(st.booleans()) else header

    def cell(v: float) -> str:
        s = fmt.format(float(v))
        return s.replace(".", ",") if decimal_comma else s

    rows = []
    for k in range(t.size):
        vals = {th: t_out[k], ph: p_out[k]}
        if temp_h:
            vals[temp_h] = 20.0 if "[C]" in temp_h else 293.15
        rows.append(delim.join(cell(vals[h]) for h in header))
    lines = ["# logger export"] * draw(st.integers(0, 2)) + [delim.join(header), *rows]
    for _ in range(0 if clean else draw(st.integers(0, 3))):  # broken lines
        k = draw(st.integers(0, len(lines)))
        lines.insert(k, draw(st.sampled_from(["", "nan,nan", "1,2,3,4,5", "abc", ",", "1e999,1",
                                              "\x00", "  ", "1;2", '"1,5",2'])))
    text = "\n".join(lines) + draw(st.sampled_from(["", "\n", "\r\n", "\n\n"]))
    opts: dict[str, Any] = {}
    if gauge_hdr and clean:
        opts["atmosphere"] = P_ATM
    if not clean:
        if draw(st.integers(0, 3)) == 0:
            opts["pressure_unit"] = draw(st.sampled_from(["Pa", "kPa", "bar", "psi", "xyz", "kpa"]))
        if draw(st.integers(0, 3)) == 0:
            opts["gauge"] = draw(st.booleans())
        if draw(st.integers(0, 2)) == 0:
            opts["atmosphere"] = draw(st.sampled_from([P_ATM, 0.0, -1.0, math.nan, math.inf,
                                                       1e5, 1e300]))
        if draw(st.integers(0, 5)) == 0:
            opts["time_column"] = draw(st.sampled_from([th, "time", "nope"]))
        if draw(st.integers(0, 7)) == 0:
            opts["delimiter"] = draw(st.sampled_from([",", ";"]))
    opts["_volume"] = cfg.volume
    if not clean and draw(st.integers(0, 3)) == 0:
        return text.encode("utf-16") if draw(st.booleans()) else text.encode("latin-1",
                                                                              "replace"), opts
    return text, opts


# ------------------------------------------------------------------------------------ bags
BAG_DAMAGE = ("flip", "truncate", "no_metadata", "garble_metadata", "mcap_path", "append")


@st.composite
def bag_cases(draw: st.DrawFn, *, max_samples: int = 3000) -> dict[str, Any]:
    """What :func:`write_bag` writes: stamps [ns], pressures [Pa], the rig configuration
    (maybe damaged), the estimator settings message (maybe junk) and the damage done to the
    files afterwards."""
    t, p, cfg = draw(wild_discharges(max_samples=max_samples))
    ok = np.isfinite(t) & (np.abs(t) < 9e9)
    t_ns = np.where(ok, np.round(np.where(ok, t, 0.0) * 1e9), 0).astype(np.int64)
    if not ok.all():
        t_ns[~ok] = draw(st.sampled_from([0, -1, 2**62, -(2**62)]))
    if draw(st.booleans()):
        t_ns = t_ns + 1_700_000_000_000_000_000
    config: dict[str, Any] | None = cfg.to_dict()
    choice = draw(st.integers(0, 5))
    if choice == 0:
        config = None
    elif choice == 1:
        config = draw(st.dictionaries(st.text(max_size=6), JUNK, max_size=4))
    elif choice == 2:
        assert config is not None
        for key in draw(st.lists(st.sampled_from(sorted(config)), max_size=3)):
            config[key] = draw(JUNK)
    elif choice == 3:
        assert config is not None
        for key in draw(st.lists(st.sampled_from(sorted(config)), max_size=3)):
            config.pop(key, None)
    settings: str | None = None
    s = draw(st.integers(0, 4))
    if s == 1:
        fields = dataclasses.asdict(EstimatorSettings(volume=cfg.volume))
        for key in draw(st.lists(st.sampled_from(sorted(fields)), max_size=2)):
            fields[key] = draw(JUNK)
        settings = json.dumps(fields, default=str)
    elif s == 2:
        settings = draw(st.sampled_from(["", "[]", "{", "null", '{"volume": "1L"}',
                                         '{"atmosphere": 0}', '{"min_plateau": 1e9}']))
    damage = draw(st.lists(st.tuples(st.sampled_from(BAG_DAMAGE), st.floats(0.0, 1.0),
                                     st.integers(0, 255)), max_size=2))
    return {"t_ns": t_ns, "p": p, "config": config, "settings": settings, "damage": damage,
            "volume": cfg.volume, "variance": draw(st.sampled_from([0.0, -1.0, math.nan]))}


def write_bag(folder: Path, case: dict[str, Any]) -> Path | None:
    """Write ``case`` (of :func:`bag_cases`) as a bag under ``folder`` with the package's
    writer, then damage its files; the path to read, or None when the writer refused the
    input (with :class:`~pneumatic_unload.io.bag.BagWriteError`, its typed error)."""
    from pneumatic_unload.io.bag import (
        MSGTYPE_CONFIG,
        TOPIC_SETTINGS,
        BagRecorder,
        BagWriteError,
        make_typestore,
    )

    bag = folder / "bag"
    try:
        with BagRecorder(bag, config=case["config"], chunk_size=4096) as rec:
            rec.write_pressures(case["t_ns"], case["p"], variance=case["variance"])
            if case["settings"] is not None:
                store = make_typestore()
                msg = store.types[MSGTYPE_CONFIG](data=case["settings"])
                rec.write_raw(TOPIC_SETTINGS, MSGTYPE_CONFIG, int(case["t_ns"][0]) if
                              case["t_ns"].size else 0,
                              store.serialize_cdr(msg, MSGTYPE_CONFIG))
    except BagWriteError:
        return None
    mcap = next(bag.glob("*.mcap"))
    path = bag
    for what, where, byte in case["damage"]:
        data = bytearray(mcap.read_bytes())
        k = min(len(data) - 1, int(where * len(data)))
        if what == "flip" and data:
            data[k] = byte
        elif what == "truncate":
            del data[k:]
        elif what == "append":
            data += bytes([byte]) * 100
        elif what == "no_metadata":
            (bag / "metadata.yaml").unlink(missing_ok=True)
        elif what == "garble_metadata" and (bag / "metadata.yaml").exists():
            meta = bytearray((bag / "metadata.yaml").read_bytes())
            meta[min(len(meta) - 1, int(where * len(meta)))] = byte
            (bag / "metadata.yaml").write_bytes(bytes(meta))
        elif what == "mcap_path":
            path = mcap
        mcap.write_bytes(bytes(data))
    return path


def read_bag_library(path: Path) -> None:
    """Every reader of :mod:`pneumatic_unload.io.bag` the CLI uses: only
    :class:`~pneumatic_unload.io.bag.BagError` may be raised."""
    from pneumatic_unload.io.bag import (
        TOPIC_SETTINGS,
        BagError,
        bag_summary,
        read_config,
        read_json_topic,
        read_pressure,
        read_temperature,
    )

    for reader in (read_pressure, read_config, read_temperature, bag_summary,
                   lambda q: read_json_topic(q, TOPIC_SETTINGS)):
        with contextlib.suppress(BagError):
            reader(path)


# ------------------------------------------------------------------------------ properties
def prop_csv(folder: Path, text: str | bytes, opts: dict[str, Any]) -> None:
    """The CSV reader raises only :class:`~pneumatic_unload.io.csvlog.CsvError`; what it
    returns is a valid trace that the estimator answers; the CLI exits 0, 1 or 2."""
    from pneumatic_unload.io.csvlog import CsvError, read_csv_trace

    opts = dict(opts)
    volume = opts.pop("_volume", 1e-3)
    path = write_csv_text(folder / "log.csv", text)
    try:
        tr = read_csv_trace(path, **opts)
    except CsvError:
        tr = None
    if tr is not None:
        t, p = np.asarray(tr.t), np.asarray(tr.p)
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(p > 0)
                and np.all(np.diff(t) > 0)):
            raise FuzzFailure("read_csv_trace returned non-finite, non-positive pressures or "
                              "non-increasing times")
        run_analyze(t, p, EstimatorSettings(volume=volume))
    argv = ["analyze", str(path), "--json", "--volume", repr(volume)]
    if "pressure_unit" in opts and opts["pressure_unit"] in ("Pa", "kPa", "bar", "psi"):
        argv += ["--pressure-unit", opts["pressure_unit"]]
    if opts.get("gauge"):
        argv += ["--gauge"]
    if "atmosphere" in opts:
        argv += ["--atmosphere", repr(opts["atmosphere"])]
    check_cli_json(*run_cli(argv))


def prop_bag(folder: Path, case: dict[str, Any]) -> None:
    """A bag written by the package's writer, maybe damaged: the readers raise only
    BagError and the CLI exits 0, 1 or 2 with a valid answer."""
    path = write_bag(folder, case)
    if path is None:
        return
    read_bag_library(path)
    argv = ["analyze", str(path), "--json"]
    if case["config"] is None or "volume" not in case["config"]:
        argv += ["--volume", repr(case["volume"])]
    check_cli_json(*run_cli(argv))


def prop_discrepancy(t: np.ndarray, p: np.ndarray, settings: Any) -> None:
    """The discrepancy workflow raises only DiscrepancyError; its C is finite and positive
    and its summary JSON-ready."""
    from pneumatic_unload.discrepancy import DiscrepancyError, find_discrepancy

    try:
        res = find_discrepancy(t, p, settings)
    except DiscrepancyError:
        return
    c = res.conductance
    if not (math.isfinite(c) and c > 0):
        raise FuzzFailure(f"discrepancy: C = {c!r}")
    json.dumps(res.to_dict(), allow_nan=False)


@st.composite
def discrepancy_cases(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, Any]:
    """A small wild discharge (<= 1500 samples) and light discrepancy settings (one or
    two candidate effects, one effect at most, no profile) [SI]."""
    from pneumatic_unload.discrepancy import DiscrepancySettings

    t, p, cfg = draw(wild_discharges(max_samples=1500))
    cands = draw(st.lists(st.sampled_from(EFFECTS), min_size=1, max_size=2, unique=True))
    tank = cfg.tank_fields()
    if draw(st.booleans()):
        tank["atmosphere"] = None
    ds = DiscrepancySettings(**tank, candidates=tuple(cands), max_effects=1, profile=False,
                             resolution=draw(st.sampled_from([0.03, 0.1])))
    return t, p, ds


# ---------------------------------------------------------- clean examples (@example)
def clean_csv() -> tuple[str, dict[str, Any]]:
    """:func:`clean_discharge` as a CSV file in kPa (a :func:`csv_files` case)."""
    t, p, cfg = clean_discharge()
    rows = "\n".join(f"{float(a)!r},{float(b) / 1e3!r}" for a, b in zip(t, p, strict=True))
    return f"Time [s],Pressure [kPa]\n{rows}\n", {"_volume": cfg.volume}


def clean_bag() -> dict[str, Any]:
    """:func:`clean_discharge` as a :func:`bag_cases` case (rig configuration, no damage)."""
    t, p, cfg = clean_discharge()
    return {"t_ns": np.round((t + 1.7e9) * 1e9).astype(np.int64), "p": p,
            "config": cfg.to_dict(), "settings": None, "damage": [], "volume": cfg.volume,
            "variance": 0.0}


def clean_discrepancy() -> tuple[np.ndarray, np.ndarray, Any]:
    """:func:`clean_discharge` with light discrepancy settings (a :func:`discrepancy_cases`
    case)."""
    from pneumatic_unload.discrepancy import DiscrepancySettings

    t, p, cfg = clean_discharge(rate=250.0)
    return t, p, DiscrepancySettings(**cfg.tank_fields(), candidates=("leak",),
                                     max_effects=1, profile=False)
