# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""CSV logs of any size (issue 13): decimal commas, rows wider than the header, assumed units,
reading in chunks, streaming through the estimator with bounded memory."""

import json
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from pneumatic_unload.analysis.records import analyze_record, open_record
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import EstimatorSettings, analyze, analyze_chunks, decisions
from pneumatic_unload.estimation.chunked import Overview
from pneumatic_unload.io import CsvFormatError, read_csv_trace
from pneumatic_unload.io.csvlog import CsvStream
from pneumatic_unload.model import simulate

REPO = Path(__file__).resolve().parents[1]


def _write(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _cli(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", *argv],
                          capture_output=True, text=True, cwd=REPO, timeout=300)


def _discharge_csv(path: Path, *, rate: float = 1000.0, pre: int = 0, post: int = 0,
                   header: str = "time [s],pressure [Pa]", seed: int = 2) -> RigConfig:
    """A simulated discharge (1 kHz), with ``pre``/``post`` extra plateau rows."""
    cfg = RigConfig(rate=rate, pre_time=1.0, seed=seed)
    sim = simulate(cfg)
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    t = np.concatenate((np.arange(pre) * dt, pre * dt + sim.t,
                        pre * dt + sim.t[-1] + np.arange(1, post + 1) * dt))
    p = np.concatenate((np.median(sim.measured[:500]) + cfg.noise_std * rng.standard_normal(pre),
                        sim.measured,
                        np.median(sim.measured[-500:]) + cfg.noise_std
                        * rng.standard_normal(post)))
    with path.open("w") as fh:
        fh.write(header + "\n")
        for k in range(0, t.size, 200_000):
            fh.write("".join(f"{a:.4f},{b:.1f}\n" for a, b in
                             zip(t[k:k + 200_000].tolist(), p[k:k + 200_000].tolist(),
                                 strict=True)))
    return cfg


# ------------------------------------------------------------------ separators and commas


@pytest.mark.parametrize("row", ["0,5,700,3", "0,700,3"])
def test_decimal_commas_with_comma_separator_are_an_error_naming_the_line(tmp_path, row):
    path = _write(tmp_path, f"# logger\ntime,pressure\n{row}\n")
    with pytest.raises(CsvFormatError, match=r"log\.csv:3: row has \d fields, more than the 2"
                                             r".*decimal commas.*';' as the separator"):
        read_csv_trace(path)


def test_row_with_more_fields_than_the_header_is_an_error(tmp_path):
    good = "time;pressure\n0;1e5\n1;1e5\n"
    path = _write(tmp_path, good + "2;1e5;7\n")
    with pytest.raises(CsvFormatError, match=r"log\.csv:4: row has 3 fields.*stray separator"):
        read_csv_trace(path)
    # an empty trailing field (a separator at the end of a row) is no extra value
    trace = read_csv_trace(_write(tmp_path, "time,pressure\n0,1e5,\n1,2e5,\n", "t.csv"))
    assert trace.p.tolist() == [1e5, 2e5]


@pytest.mark.parametrize("sep", [";", "\t"])
def test_semicolon_or_tab_file_with_decimal_commas_is_read(tmp_path, sep):
    text = f"Time [s]{sep}Pressure [kPa]\n0,5{sep}700,3\n1,25{sep}650\n2{sep}6,5e2\n"
    trace = read_csv_trace(_write(tmp_path, text))
    assert trace.t.tolist() == [0.5, 1.25, 2.0]
    assert trace.p == pytest.approx([700_300.0, 650_000.0, 650_000.0])
    assert trace.source.decimal_comma and trace.source.delimiter == sep
    # a thousands separator is not a decimal comma: named, with its line
    bad = _write(tmp_path, f"time{sep}pressure\n0{sep}1,234.5\n", "b.csv")
    with pytest.raises(CsvFormatError, match=r"b\.csv:2 \(data row 1\).*'1,234\.5'"):
        read_csv_trace(bad)


def test_cli_decimal_comma_file_one_line_error(tmp_path):
    rows = "".join(f"{k},0,7{k}0,5\n" for k in range(40))
    path = _write(tmp_path, "time [s],pressure [kPa]\n" + rows)
    proc = _cli("analyze", str(path), "--volume", "0.005")
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "log.csv:2: row has 4 fields" in lines[0] and "separator" in lines[0]


# ------------------------------------------------------------------ assumed units


def test_units_not_stated_are_named_as_assumed(tmp_path):
    path = _write(tmp_path, "time,pressure,temp\n0,1e5,20\n1,1e5,20\n")
    warnings = read_csv_trace(path).source.warnings
    assert len(warnings) == 3
    pressure = next(w for w in warnings if "(pressure)" in w)
    assert "'pressure'" in pressure and "Pa assumed" in pressure
    # the library's words from the library, the command line's with hints="cli"
    assert "pressure_unit=" in pressure and "'pressure [kPa]'" in pressure
    assert "--pressure-unit" not in pressure
    cli = read_csv_trace(path, hints="cli").source.warnings
    assert any("--pressure-unit UNIT" in w and "pressure_unit=" not in w for w in cli)
    assert any("(time)" in w and "s assumed" in w for w in warnings)
    assert any("(temperature)" in w and "C assumed" in w for w in warnings)
    # a stated unit (header or argument) is not warned about
    stated = read_csv_trace(path, pressure_unit="kPa", time_unit="s", temperature_unit="C")
    assert stated.source.warnings == ()
    header = _write(tmp_path, "time [s],pressure [kPa]\n0,100\n1,100\n", "h.csv")
    assert read_csv_trace(header).source.warnings == ()


def test_cli_warns_about_the_assumed_pressure_unit(tmp_path):
    path = tmp_path / "run.csv"
    cfg = _discharge_csv(path, header="time,pressure")
    proc = _cli("analyze", str(path), "--volume", repr(cfg.volume), "--atmosphere",
                repr(cfg.atmosphere), "--no-curve-fit", "--json")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    warned = [ln for ln in proc.stderr.splitlines() if "(pressure)" in ln]
    assert len(warned) == 1 and "warning" in warned[0] and "Pa assumed" in warned[0]
    assert "--pressure-unit UNIT" in warned[0] and "pressure_unit=" not in warned[0]
    doc = json.loads(proc.stdout)
    assert any("Pa assumed" in w for w in doc["input_warnings"])
    quiet = _cli("analyze", str(path), "--volume", repr(cfg.volume), "--atmosphere",
                 repr(cfg.atmosphere), "--no-curve-fit", "--pressure-unit", "Pa",
                 "--time-unit", "s")
    assert quiet.returncode == 0 and "assumed" not in quiet.stderr


# ------------------------------------------------------------------ chunks and streaming


def test_small_chunks_read_the_same_arrays(tmp_path):
    path = tmp_path / "run.csv"
    _discharge_csv(path)
    whole = read_csv_trace(path)
    stream = CsvStream(path, chunk_bytes=4096)
    chunks = list(stream)
    assert len(chunks) > 100  # really read in pieces
    assert stream.rows == whole.source.rows == sum(c.t.size for c in chunks)
    assert np.array_equal(np.concatenate([c.t for c in chunks]), whole.t)
    assert np.array_equal(np.concatenate([c.p for c in chunks]), whole.p)
    # a bad row deep in the file is named by its line whatever the chunk holding it
    lines = path.read_text().splitlines()
    lines[5000] = lines[5000].replace(",", ",x")
    path.write_text("\n".join(lines) + "\n")
    for size in (4096, 1 << 23):
        with pytest.raises(CsvFormatError, match=r"run\.csv:5001 \(data row 5000\)"):
            list(CsvStream(path, chunk_bytes=size))


@pytest.mark.parametrize("case", ["normal", "aborted", "no_unload"])
def test_streamed_analysis_equals_whole_file_analysis(tmp_path, case):
    path = tmp_path / "run.csv"
    cfg = {"normal": {}, "aborted": {"valve_close_time": 3.0}}.get(case)
    if cfg is None:  # a plateau only: the no-unload reason must be the same too
        path.write_text("time [s],pressure [Pa]\n" + "".join(
            f"{k * 1e-3:.4f},{7e5 + 900.0 * np.sin(k * 1.7):.1f}\n" for k in range(5000)))
    else:
        sim = simulate(RigConfig(rate=1000.0, pre_time=1.0, seed=4, **cfg))
        path.write_text("time [s],pressure [Pa]\n" + "".join(
            f"{a:.4f},{b:.1f}\n" for a, b in zip(sim.t.tolist(), sim.measured.tolist(),
                                                 strict=True)))
    settings = EstimatorSettings(volume=0.005, atmosphere=101325.0)
    trace = read_csv_trace(path)
    whole = analyze(trace.t, trace.p, settings)
    assert (len(whole) > 0) == (case != "no_unload")
    for size in (2048, 65536, 1 << 23):
        run = analyze_record(open_record(path, chunk_bytes=size), settings)
        assert run.samples == trace.t.size
        assert [r.to_dict() for r in run.published] == [r.to_dict() for r in whole]
    if case == "no_unload":
        from pneumatic_unload.estimation import explain_no_unload

        assert run.explain_no_unload() == explain_no_unload(trace.t, trace.p, settings)


def test_overview_keeps_every_stride_th_sample_in_bounded_memory():
    ov = Overview(capacity=1000)
    t = np.arange(12_345, dtype=float)
    for k in range(0, t.size, 777):
        ov.add(t[k:k + 777], -t[k:k + 777])
    tt, pp = ov.arrays()
    assert ov.stride == 8 and tt.size <= 2000
    assert np.array_equal(tt, t[::8]) and np.array_equal(pp, -t[::8])


def test_long_plateau_is_trimmed_without_changing_the_result(tmp_path, monkeypatch):
    """An idle plateau of 300 k samples before the unload: with IDLE_KEEP at 32 k the
    estimator's buffer stays bounded, and the result is the one without trimming."""
    path = tmp_path / "run.csv"
    cfg = _discharge_csv(path, pre=300_000)
    trace = read_csv_trace(path)
    settings = EstimatorSettings(volume=cfg.volume, atmosphere=cfg.atmosphere,
                                 curve_fit=False)
    untrimmed = analyze(trace.t, trace.p, settings)
    monkeypatch.setattr(decisions, "IDLE_KEEP", 1 << 15)
    from pneumatic_unload.estimation import StreamingEstimator

    est = StreamingEstimator(settings)
    longest = 0
    for k in range(0, 290_000, 10_000):  # the plateau only
        est.push_block(trace.t[k:k + 10_000], trace.p[k:k + 10_000])
        longest = max(longest, len(est.buffer))
    bound = max(2 * (1 << 15), (1 << 15) + decisions.TRIM_MIN) + 10_000  # + one block
    assert est.buffer.shift > 150_000 and longest <= bound
    trimmed = analyze(trace.t, trace.p, settings)
    assert len(untrimmed) == 1
    assert [r.to_dict() for r in trimmed] == [r.to_dict() for r in untrimmed]


def test_streamed_analysis_memory_does_not_scale_with_the_record(tmp_path, monkeypatch):
    """A 1 M-row log (a discharge inside a long idle record) analysed in 256 KiB chunks
    peaks below 16 B per row: less than its time and pressure arrays alone would take (the
    whole-file analysis held them, and 32 B per row in the estimator's buffer)."""
    path = tmp_path / "long.csv"
    cfg = _discharge_csv(path, pre=600_000, post=340_000)
    monkeypatch.setattr(decisions, "IDLE_KEEP", 1 << 16)
    settings = EstimatorSettings(volume=cfg.volume, atmosphere=cfg.atmosphere)
    rows = 1_000_000
    tracemalloc.start()
    try:
        stream = CsvStream(path, chunk_bytes=1 << 18)
        run = analyze_chunks(((c.t, c.p) for c in stream), settings,
                             overview_samples=1 << 16)
        _now, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert abs(run.samples - rows) < 70_000
    assert [r.status for r in run.published if r.final] == ["ok"]
    assert peak < 16 * run.samples, f"peak {peak / 2**20:.1f} MiB"
