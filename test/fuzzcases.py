"""Property-based fuzzing of the package's input boundary (issue #13): hypothesis strategies
and the properties every input must satisfy, shared by ``test/test_fuzz.py`` (a short
profile in ``make test``) and ``bench/bench_fuzz.py`` (the long run).

A *failure* is any exception other than the package's typed errors (the ones the command
line turns into a one-line message), a hang (each example is bounded by :func:`time_limit`),
or a result with status "ok" whose C, tau_exp or a sigma is non-finite or not positive.

Inputs are realistic-but-wild: simulated discharges (:func:`pneumatic_unload.model.simulate`
of a random :class:`~pneumatic_unload.config.RigConfig`) with random corruption (NaN, inf,
spikes, reversed or duplicate stamps, clock steps, clipping, stuck sensor, huge or tiny
values, gauge-like offsets, ...), next to plain random arrays, which never get past the
detector. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from pneumatic_unload.config import EFFECTS, RigConfig
from pneumatic_unload.config.fields import describe
from pneumatic_unload.estimation import (
    STATUSES,
    EstimationError,
    EstimatorSettings,
    UnloadResult,
    analyze,
    explain_no_unload,
    gauge_suspicion,
    merge_final,
)
from pneumatic_unload.model import simulate

P_ATM = 101325.0  # [Pa]


class FuzzFailure(AssertionError):
    """A property of the input boundary does not hold (the fuzz run's failure)."""


class Hang(FuzzFailure):
    """One example ran longer than its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise :class:`Hang` in the main thread if the block runs longer than ``seconds`` [s]."""
    def on_alarm(_sig: int, _frame: object) -> None:
        raise Hang(f"example ran longer than {seconds:g} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


# ------------------------------------------------------------------------------- checks
def check_results(results: list[UnloadResult], where: str = "analyze") -> None:
    """Every result has a known status; an 'ok' one has finite, positive C, tau_exp and
    sigmas; every result is JSON-ready (the CLI's ``--json``)."""
    for r in results:
        if r.status not in STATUSES:
            raise FuzzFailure(f"{where}: unknown status {r.status!r}")
        d = r.to_dict()
        d.pop("extra", None)
        json.dumps(d, allow_nan=False)
        if r.status != "ok":
            continue
        must = {"conductance": r.conductance, "tau_exp": r.tau_exp, "p10": r.p10,
                "p_atm": r.p_atm}
        maybe = {"conductance_model": r.conductance_model, "tau_exp_model": r.tau_exp_model,
                 "critical_ratio": r.critical_ratio}
        sigmas = {"tau_exp_std": r.tau_exp_std, "conductance_model_std":
                  r.conductance_model_std, "critical_ratio_std": r.critical_ratio_std,
                  "noise_std": r.noise_std}
        bad = [f"{k}={v!r}" for k, v in must.items() if not (math.isfinite(v) and v > 0)]
        bad += [f"{k}={v!r}" for k, v in maybe.items() if not (math.isnan(v) or
                                                             (math.isfinite(v) and v > 0))]
        bad += [f"{k}={v!r}" for k, v in sigmas.items() if not (math.isnan(v) or
                                                              (math.isfinite(v) and v >= 0))]
        if not r.tau_exp_std > 0:
            bad.append(f"tau_exp_std={r.tau_exp_std!r}")
        if bad:
            raise FuzzFailure(f"{where}: status ok (final={r.final}) with " + ", ".join(bad))


def run_analyze(t: np.ndarray, p: np.ndarray, s: EstimatorSettings) -> list[UnloadResult]:
    """The library path of ``pneumatic-unload analyze``: analyze, merge, explain, gauge
    check; only :class:`EstimationError` may be raised."""
    try:
        published = analyze(t, p, s)
    except EstimationError:
        return []
    check_results(published)
    unloads = merge_final(published)
    why = None if unloads else explain_no_unload(t, p, s)
    if not unloads and not (isinstance(why, str) and why):
        raise FuzzFailure(f"no unload and no reason: {why!r}")
    gauge_suspicion(t, p, s)
    return published


# --------------------------------------------------------------------------- strategies
def _field_value(f: dict[str, Any]) -> st.SearchStrategy[Any]:
    """A valid value of one settings field from its metadata (bounds included)."""
    kind = f["kind"]
    if kind == "flag":
        return st.booleans()
    if kind == "choice":
        return st.sampled_from(f["choices"])
    if kind == "integer":
        return st.one_of(st.integers(f["min"], min(f["max"], 4096)),
                         st.sampled_from([f["min"], f["max"]]))
    lo, hi = f["min"], f["max"]
    vals = st.floats(lo, hi, allow_nan=False)
    if lo > 0:
        vals = st.one_of(vals, st.floats(math.log10(lo), math.log10(hi)).map(lambda e: 10 ** e))
    if kind == "optional":
        return st.one_of(st.none(), vals)
    return vals


@st.composite
def estimator_settings(draw: st.DrawFn, near: EstimatorSettings | None = None
                       ) -> EstimatorSettings:
    """Estimator settings: some fields drawn anywhere in their range, the others those of
    ``near`` (the rig's own) or the defaults."""
    base = dataclasses.asdict(near or EstimatorSettings())
    for f in describe(EstimatorSettings):
        if draw(st.integers(0, 4)) == 0:
            base[f["name"]] = draw(_field_value(f))
    if base["signal_gain"] == 0:
        base["signal_gain"] = 1.0
    return EstimatorSettings(**base)


@st.composite
def rig_configs(draw: st.DrawFn, *, max_samples: int = 6000) -> RigConfig:
    """A simulated rig: tank, component, sensor and effects drawn over wide ranges, with a
    record of at most ``max_samples`` samples."""
    kw: dict[str, Any] = {
        "volume": 10 ** draw(st.floats(-4.5, -1.5)),
        "conductance": 10 ** draw(st.floats(-10.0, -7.5)),
        "initial_pressure": draw(st.sampled_from([1.5e5, 3e5, 7e5, 1.2e6, 5e6])),
        "critical_ratio": draw(st.floats(0.1, 0.6)),
        "noise_std": draw(st.sampled_from([0.0, 10.0, 300.0, 1000.0, 3e4])),
        "seed": draw(st.integers(0, 2**31 - 1)),
        "pre_time": draw(st.sampled_from([0.0, 0.01, 0.1, 0.3, 1.0])),
        "initial_temperature": draw(st.floats(250.0, 350.0)),
        "length_diameter_ratio": draw(st.floats(0.5, 10.0)),
    }
    if draw(st.booleans()):
        kw["effects"] = tuple(draw(st.sets(st.sampled_from(EFFECTS), max_size=3)))
    if draw(st.integers(0, 5)) == 0:
        kw["valve_close_time"] = draw(st.floats(0.01, 2.0))
    if draw(st.integers(0, 5)) == 0:
        kw["quantization"] = draw(st.sampled_from([100.0, 1000.0, 2e4]))
    if draw(st.integers(0, 5)) == 0:
        kw["noise_ar_rho"], kw["noise_ar_std"] = draw(st.floats(0.0, 0.99)), 500.0
    cfg = RigConfig(**kw)
    tau = cfg.volume / (cfg.conductance * 287.0 * 293.15) * 2.0  # rough discharge time [s]
    duration = draw(st.floats(0.5, 8.0)) * tau
    rate = draw(st.sampled_from([50.0, 200.0, 1000.0, 5000.0]))
    duration = min(duration, 30_000.0)
    rate = min(rate, max_samples / (cfg.pre_time + duration + 1e-3))
    if rate < 1.0:
        duration, rate = max_samples - 1.0, 1.0
    return cfg.replace(duration=duration, rate=rate)


CORRUPTIONS = ("nan", "inf", "nan_t", "spikes", "reverse", "reverse_block", "duplicate",
               "clock_back", "clip", "stuck", "huge", "tiny", "gauge", "negative", "drop",
               "quantize", "time_scale", "time_offset", "truncate", "repeat", "constant",
               "zero", "denormal", "ramp")


def corrupt(draw: st.DrawFn, t: np.ndarray, p: np.ndarray, what: str
            ) -> tuple[np.ndarray, np.ndarray]:
    """Apply one corruption ``what`` (of :data:`CORRUPTIONS`) at drawn places."""
    n = t.size
    t, p = t.copy(), p.copy()
    i = draw(st.integers(0, max(n - 1, 0)))
    j = min(n, i + draw(st.integers(1, max(1, n // 4))))
    idx = draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=20)) if n else []
    if what == "nan":
        p[idx] = np.nan
    elif what == "inf":
        p[idx] = draw(st.sampled_from([np.inf, -np.inf]))
    elif what == "nan_t":
        t[idx] = draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    elif what == "spikes":
        p[idx] += draw(st.sampled_from([-1e6, -1e5, 1e5, 1e7, 1e12]))
    elif what == "reverse":
        t = t[::-1].copy()
    elif what == "reverse_block":
        t[i:j] = t[i:j][::-1]
    elif what == "duplicate":
        t[i:j] = t[i]
    elif what == "clock_back":
        t[i:] -= draw(st.sampled_from([1e-3, 0.1, 10.0, 1e6]))
    elif what == "clip":
        lo, hi = float(np.nanmin(p)), float(np.nanmax(p))
        p = np.minimum(p, lo + draw(st.floats(0.0, 1.0)) * (hi - lo))
    elif what == "stuck":
        p[i:j] = p[i]
    elif what == "huge":
        p *= draw(st.sampled_from([1e30, 1e100, 1e300, -1e300]))
    elif what == "tiny":
        p *= draw(st.sampled_from([1e-30, 1e-300, 1e-320]))
    elif what == "gauge":
        p -= draw(st.sampled_from([P_ATM, 1e5, 2 * P_ATM]))
    elif what == "negative":
        p = -p
    elif what == "drop":
        keep = np.ones(n, bool)
        keep[i:j] = False
        t, p = t[keep], p[keep]
    elif what == "quantize":
        q = draw(st.sampled_from([1e3, 1e5, 1e6]))
        p = np.round(p / q) * q
    elif what == "time_scale":
        t *= draw(st.sampled_from([1e-9, 1e-3, 1e3, 1e9]))
    elif what == "time_offset":
        t += draw(st.sampled_from([-1e9, 1.7e9, 1e15, 1e300]))
    elif what == "truncate":
        t, p = t[i:j], p[i:j]
    elif what == "repeat":
        t = np.concatenate([t, t[-1] + (t - t[0]) + (t[1] - t[0] if n > 1 else 1.0)])
        p = np.concatenate([p, p])
    elif what == "constant":
        p[:] = draw(st.sampled_from([0.0, 1.0, P_ATM, 7e5]))
    elif what == "zero":
        p[i:j] = 0.0
    elif what == "denormal":
        p[idx] = 5e-324
    elif what == "ramp":
        p += np.linspace(0.0, draw(st.sampled_from([-1e6, -1e4, 1e4, 1e6])), n)
    return t, p


@st.composite
def wild_discharges(draw: st.DrawFn, *, max_samples: int = 6000
                    ) -> tuple[np.ndarray, np.ndarray, RigConfig]:
    """A simulated discharge (t [s], measured p [Pa]) with 0-3 random corruptions."""
    cfg = draw(rig_configs(max_samples=max_samples))
    sim = simulate(cfg)
    t, p = sim.t, sim.measured
    for what in draw(st.lists(st.sampled_from(CORRUPTIONS), max_size=3)):
        t, p = corrupt(draw, t, p, what)
    return t, p, cfg


@st.composite
def random_traces(draw: st.DrawFn, *, max_samples: int = 400
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Plain random arrays: stamps (regular, jittered, random, constant) and values (any
    float, steps, levels)."""
    n = draw(st.integers(0, max_samples))
    kind = draw(st.sampled_from(["regular", "jitter", "random", "constant"]))
    if kind == "regular":
        dt = draw(st.floats(1e-12, 1e6))
        t = draw(st.floats(-1e12, 1e12)) + dt * np.arange(n, dtype=float)
    elif kind == "jitter":
        t = np.cumsum(np.abs(np.asarray(draw(st.lists(st.floats(-1.0, 10.0), min_size=n,
                                                            max_size=n)), float)))
    elif kind == "random":
        t = np.asarray(draw(st.lists(st.floats(), min_size=n, max_size=n)), float)
    else:
        t = np.full(n, draw(st.floats(allow_nan=False)))
    vals = st.one_of(st.floats(), st.floats(-1e7, 1e7), st.sampled_from([0.0, P_ATM, 7e5]))
    if draw(st.booleans()):
        p = np.asarray(draw(st.lists(vals, min_size=n, max_size=n)), float)
    else:  # piecewise levels: a plateau, a drop, a plateau
        a, b = draw(vals), draw(vals)
        k = draw(st.integers(0, n))
        p = np.where(np.arange(n) < k, a, b).astype(float)
        p += np.asarray(draw(st.lists(st.floats(-1e3, 1e3), min_size=n, max_size=n)), float)
    return t, p


# ------------------------------------------------------------------------------- CLI glue
def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``pneumatic-unload ARGV`` in-process: (exit status, stdout, stderr). Exit statuses
    0, 1 and 2 are answers; a traceback is a failure (raised as is)."""
    from pneumatic_unload.cli import main

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
JUNK = st.one_of(st.none(), st.booleans(), st.integers(-10, 10**20), st.floats(),
                 st.text(max_size=8), st.lists(st.integers(), max_size=3),
                 st.dictionaries(st.text(max_size=4), st.integers(), max_size=2))
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
def prop_settings(kw: dict[str, Any]) -> None:
    """Settings from any keyword values: valid, or refused with the settings class's
    typed error."""
    from pneumatic_unload.discrepancy import DiscrepancyError, DiscrepancySettings

    for cls, err in ((EstimatorSettings, EstimationError),
                     (DiscrepancySettings, DiscrepancyError)):
        known = {f.name for f in dataclasses.fields(cls)}
        with contextlib.suppress(err):
            cls(**{k: v for k, v in kw.items() if k in known})


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


def settings_keywords() -> st.SearchStrategy[dict[str, Any]]:
    """Keyword arguments for the settings classes: any field, any junk value."""
    from pneumatic_unload.discrepancy import DiscrepancySettings

    names = sorted({f.name for c in (EstimatorSettings, DiscrepancySettings)
                    for f in dataclasses.fields(c)})
    return st.dictionaries(st.sampled_from(names), JUNK, max_size=4)
