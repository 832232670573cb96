# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Logger files as they come (issues 54 and 55): date-time time columns, epoch stamps,
pressure columns by the names loggers write, hPa and mbar, a counter that wraps, a torn last
row, UTF-16 and UTF-8 with a byte-order mark; hints in the caller's words."""

import datetime as dt
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pneumatic_unload.app.cli import main
from pneumatic_unload.config import RigConfig
from pneumatic_unload.io import CsvFormatError, CsvOptionError, read_csv_trace
from pneumatic_unload.model import simulate

REPO = Path(__file__).resolve().parents[1]
T0 = dt.datetime(2026, 3, 4, 10, 15, 2, 125000)


def _write(path: Path, text: str, encoding: str = "utf-8", bom: bytes = b"") -> Path:
    path.write_bytes(bom + text.encode(encoding))
    return path


@pytest.fixture(scope="module")
def discharge():
    """A simulated discharge at 200 Hz: (t [s], p [Pa], gas T [K], the rig)."""
    cfg = RigConfig(rate=200.0, pre_time=1.0, seed=3)
    sim = simulate(cfg)
    return sim.t, sim.measured, sim.temperature, cfg


def _analyze(capsys, path: Path, cfg: RigConfig, *extra: str) -> dict:
    code = main(["analyze", str(path), "--volume", repr(cfg.volume), "--json", *extra])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


def _final_c(doc: dict) -> float:
    (u,) = [x for x in doc["unloads"] if x["final"]]
    return u["recommended"]["conductance"]


# ------------------------------------------------------------------ 1. date-time columns
_ZONES = st.sampled_from([None, dt.UTC, dt.timezone(dt.timedelta(hours=1)),
                          dt.timezone(dt.timedelta(hours=-5, minutes=-30))])


@settings(max_examples=40, deadline=None)
@given(start=st.datetimes(min_value=dt.datetime(2001, 1, 1),
                          max_value=dt.datetime(2098, 12, 31)),
       steps_ms=st.lists(st.integers(1, 90_000_000), min_size=1, max_size=30),
       zone=_ZONES, sep=st.sampled_from([" ", "T"]),
       spec=st.sampled_from(["milliseconds", "microseconds", "seconds"]))
def test_iso_date_times_round_trip(tmp_path_factory, start, steps_ms, zone, sep, spec):
    """ISO 8601 date-times with or without a zone (over midnight, month and year ends) read
    as seconds from the first row, to the precision written (was refused: 'non-numeric
    value')."""
    start = start.replace(tzinfo=zone)
    if spec == "seconds":
        start = start.replace(microsecond=0)
        steps_ms = [max(1, s // 1000) * 1000 for s in steps_ms]
    elif spec == "milliseconds":
        start = start.replace(microsecond=start.microsecond // 1000 * 1000)
    offsets = np.cumsum([0, *steps_ms]) / 1000.0
    stamps = [start + dt.timedelta(seconds=float(s)) for s in offsets]
    rows = "".join(f"{s.isoformat(sep=sep, timespec=spec)},{7e5 - k}\n"
                   for k, s in enumerate(stamps))
    folder = tmp_path_factory.mktemp("iso")
    path = _write(folder / "log.csv", "Timestamp,p [Pa]\n" + rows)
    trace = read_csv_trace(path)
    np.testing.assert_allclose(trace.t, offsets, rtol=0, atol=2e-6)
    assert trace.source.time_form == "date-time"
    assert trace.source.time_origin == stamps[0].isoformat(sep=sep, timespec=spec)
    # blank lines send the rows through the row-by-row parser: the same times
    gaps = _write(folder / "gaps.csv", "Timestamp,p [Pa]\n" + rows.replace("\n", "\n\n"))
    np.testing.assert_allclose(read_csv_trace(gaps, chunk_bytes=64).t, offsets, rtol=0,
                               atol=2e-6)


_LOGGER_FORMS = {
    # date cell, time cell (one column each) as loggers write them
    "german": ("{d:%d.%m.%Y}", "{d:%H:%M:%S},{ms:03d}", ";"),
    "iso-date": ("{d:%Y-%m-%d}", "{d:%H:%M:%S}.{ms:03d}", ","),
    "us-ampm": ("{d:%m/%d/%Y}", "{d:%I:%M:%S}.{ms:03d} {d:%p}", ","),
    "uk": ("{d:%d/%m/%Y}", "{d:%H:%M:%S}.{ms:03d}", ","),
}


@settings(max_examples=30, deadline=None)
@given(form=st.sampled_from(sorted(_LOGGER_FORMS)),
       start=st.datetimes(min_value=dt.datetime(2020, 1, 1),
                          max_value=dt.datetime(2030, 12, 31)),
       steps_ms=st.lists(st.integers(1, 7_200_000), min_size=1, max_size=30))
def test_date_and_time_columns_round_trip(tmp_path_factory, form, start, steps_ms):
    """A date column and a time-of-day column (German 04.03.2026;10:15:02,125, US with
    AM/PM, UK day first): seconds from the first row, over midnight (was refused: 'no time
    column found by name' for Datum/Zeit, 'non-numeric value' for Date/Time)."""
    date_fmt, time_fmt, sep = _LOGGER_FORMS[form]
    start = start.replace(microsecond=start.microsecond // 1000 * 1000)
    offsets = np.cumsum([0, *steps_ms]) / 1000.0
    head = sep.join(("Datum", "Zeit", "Druck [bar]") if form == "german"
                    else ("Date", "Time", "P [bar]"))
    rows = []
    for k, s in enumerate(offsets):
        d = start + dt.timedelta(seconds=float(s))
        cells = (date_fmt.format(d=d), time_fmt.format(d=d, ms=d.microsecond // 1000),
                 f"{7 - k * 1e-3:.3f}".replace(".", "," if sep == ";" else "."))
        rows.append(sep.join(cells))
    path = _write(tmp_path_factory.mktemp("dt") / "log.csv", head + "\n" + "\n".join(rows)
                  + "\n")
    try:
        trace = read_csv_trace(path)
    except CsvFormatError as err:
        # day/month order that no date of the record tells (every day <= 12, no day after
        # the next): refused by name, never read in the other order
        assert "day/month or month/day cannot be told" in str(err)
        return
    np.testing.assert_allclose(trace.t, offsets, rtol=0, atol=2e-6)
    assert trace.source.time_form == "time of day" and trace.source.date_column is not None
    gaps = _write(path.with_name("gaps.csv"), path.read_text().replace("\n", "\n\n"))
    np.testing.assert_allclose(read_csv_trace(gaps, chunk_bytes=64).t, offsets, rtol=0,
                               atol=2e-6)


@pytest.mark.parametrize("kind", ["iso", "iso-zone", "german"])
def test_date_time_logs_give_the_number_of_seconds_logs(tmp_path, capsys, discharge, kind):
    """The same discharge logged with date-times gives the C of its logger-clock log."""
    t, p, _temp, cfg = discharge
    tz = dt.timezone(dt.timedelta(hours=1))
    rows = []
    for a, b in zip(t.tolist(), p.tolist(), strict=True):
        d = T0 + dt.timedelta(seconds=a)
        if kind == "iso":
            rows.append(f"{d.isoformat(sep=' ', timespec='milliseconds')},{b:.1f}")
        elif kind == "iso-zone":
            rows.append(f"{d.replace(tzinfo=tz).isoformat(timespec='milliseconds')},{b:.1f}")
        else:
            rows.append(f"{d:%d.%m.%Y};{d:%H:%M:%S},{d.microsecond // 1000:03d};"
                        f"{b / 1e5:.6f}".replace(".", ",", 0))
    head = "Datum;Zeit;Druck [bar]" if kind == "german" else "Timestamp,Pressure [Pa]"
    if kind == "german":
        rows = [r.rsplit(";", 1)[0] + ";" + r.rsplit(";", 1)[1].replace(".", ",")
                for r in rows]
    dated = _write(tmp_path / "dated.csv", head + "\n" + "\n".join(rows) + "\n")
    plain = _write(tmp_path / "plain.csv", "time [s],pressure [Pa]\n" + "".join(
        f"{a:.3f},{b:.1f}\n" for a, b in zip(t.tolist(), p.tolist(), strict=True)))
    c_dated = _final_c(_analyze(capsys, dated, cfg))
    c_plain = _final_c(_analyze(capsys, plain, cfg))
    assert c_dated == pytest.approx(c_plain, rel=1e-4)
    assert c_dated == pytest.approx(cfg.conductance, rel=0.01)


def test_a_mixed_or_unparsable_time_column_names_the_row(tmp_path):
    cases = {
        "Timestamp,p [Pa]\n2026-03-04 10:15:02.125,7e5\n2026-03-04 10:15:02.5,6e5\n"
        "yesterday,5e5\n": r"mixed\.csv:4 \(data row 3\): 'yesterday'.*not a date-time",
        "Timestamp,p [Pa]\n2026-03-04 10:15:02.125,7e5\n2026-03-04 10:15:02.5+01:00,6e5\n":
            r"data row 2\).*has a zone unlike the first row's",
        "time [s],p [Pa]\n0.0,7e5\n2026-03-04 10:15:02.5,6e5\n":
            r"data row 2\).*date-time after the first row's number '0.0'",
        "Timestamp,p [Pa]\n2026-02-30 10:15:02.125,7e5\n":
            r"data row 1\).*'2026-02-30' is not a date",
        "Date,Time,p [Pa]\n03/04/2026,23:59:59.5,7e5\n05/04/2026,00:00:00.3,6e5\n":
            r"data row 2\).*day/month or month/day cannot be told",
    }
    for text, pattern in cases.items():
        with pytest.raises(CsvFormatError, match=pattern):
            read_csv_trace(_write(tmp_path / "mixed.csv", text))
    with pytest.raises(CsvOptionError, match=r"holds date-times.*leave time_unit out"):
        read_csv_trace(_write(tmp_path / "u.csv", "Timestamp,p [Pa]\n"
                              "2026-03-04 10:15:02.125,7e5\n"), time_unit="ms")


@pytest.mark.parametrize(("scale", "unit"), [(1.0, "s"), (1e3, "ms")])
def test_epoch_stamps_are_told_by_magnitude_and_counted_from_the_first_row(
        tmp_path, scale, unit):
    """Epoch seconds and milliseconds (was: ms read as s, 'stamp beyond +-9.2e+09 s')."""
    from pneumatic_unload.io.csvtime import EPOCH_RANGE_S

    first = 1_772_615_702.125
    assert EPOCH_RANGE_S[0] < first < EPOCH_RANGE_S[1]
    rows = "".join(f"{round((first + k * 0.005) * scale, 3)!r},{7e5 - k}\n"
                   for k in range(50))
    trace = read_csv_trace(_write(tmp_path / "e.csv", "time,p [Pa]\n" + rows))
    np.testing.assert_allclose(trace.t, np.arange(50) * 0.005, atol=1e-6)
    src = trace.source
    assert (src.time_form, src.time_unit, src.time_unit_from) == ("epoch", unit, "values")
    assert src.time_origin == "2026-03-04T09:15:02.125Z"
    (note,) = src.warnings
    assert f"epoch stamps in {unit}" in note and "told by the magnitude" in note
    # a clock that does not reach the range is kept as it is, its unit assumed
    clock = read_csv_trace(_write(tmp_path / "c.csv", "time,p [Pa]\n100,7e5\n101,6e5\n"))
    assert clock.t.tolist() == [100.0, 101.0] and clock.source.time_form == "number"


# ------------------------------------------------------------------ 2. pressure names
@pytest.mark.parametrize(("header", "unit", "scale"), [
    ("P_Tank [bar]", "bar", 1e5), ("P_Tank (bar)", "bar", 1e5), ("p_tank", "Pa", 1.0),
    ("Druck [bar]", "bar", 1e5), ("Tankdruck (kPa)", "kPa", 1e3), ("pressure", "Pa", 1.0),
    ("P1 [psi]", "psi", 6894.757293168361), ("p_bar", "bar", 1e5), ("P [mbar]", "mbar", 1e2),
])
def test_pressure_columns_found_by_the_names_loggers_write(tmp_path, header, unit, scale):
    path = _write(tmp_path / "p.csv", f"Time [s],{header},p_atm [kPa],P_amb [bar]\n"
                                      "0,7,101,1\n1,6,101,1\n")
    trace = read_csv_trace(path)
    assert trace.source.pressure_column == header
    assert trace.source.pressure_unit == unit
    np.testing.assert_allclose(trace.p, np.array([7.0, 6.0]) * scale)


def test_hints_are_in_the_callers_words(tmp_path, capsys):
    """The library says pressure_column=, the command line --pressure-column NAME (was:
    'pass pressure_column=' on the command line)."""
    path = _write(tmp_path / "v.csv", "time [s],volts\n0,1\n1,2\n")
    with pytest.raises(CsvFormatError, match=r"pass pressure_column=$"):
        read_csv_trace(path)
    with pytest.raises(CsvFormatError, match=r"pass --pressure-column NAME$"):
        read_csv_trace(path, hints="cli")
    assert main(["analyze", str(path), "--volume", "1L"]) == 2
    err = capsys.readouterr().err
    assert "--pressure-column NAME" in err and "pressure_column=" not in err
    assert err.count(str(path)) == 1  # the file named once
    two = _write(tmp_path / "two.csv", "time [s],P_Tank [bar],P_Supply [bar]\n0,7,8\n")
    assert main(["analyze", str(two), "--volume", "1L"]) == 2
    err = capsys.readouterr().err
    assert "several columns look like pressure" in err and "--pressure-column NAME" in err
    gauge = _write(tmp_path / "g.csv", "time [s],p [kPa]\n0,500\n1,-1\n")
    with pytest.raises(CsvFormatError, match=r"pass gauge=True, atmosphere="):
        read_csv_trace(gauge)
    with pytest.raises(CsvFormatError, match=r"pass --gauge --atmosphere PA\)"):
        read_csv_trace(gauge, hints="cli")
    with pytest.raises(CsvOptionError, match="hints="):
        read_csv_trace(gauge, hints="CLI")


# ------------------------------------------------------------------ 3. hPa and mbar
@pytest.mark.parametrize("unit", ["hPa", "mbar", "hpa", "MBAR"])
def test_cli_pressure_unit_accepts_hpa_and_mbar(tmp_path, capsys, discharge, unit):
    t, p, _temp, cfg = discharge
    path = _write(tmp_path / "h.csv", "time [s],pressure\n" + "".join(
        f"{a:.3f},{b / 100:.3f}\n" for a, b in zip(t.tolist(), p.tolist(), strict=True)))
    doc = _analyze(capsys, path, cfg, "--pressure-unit", unit)
    assert _final_c(doc) == pytest.approx(cfg.conductance, rel=0.01)


# ------------------------------------------------------------------ 4. a counter that wraps
@pytest.mark.parametrize(("modulus", "start"), [(1 << 16, 60_000), (1 << 32, 2**32 - 3000)])
def test_a_wrapping_ms_counter_is_unwrapped(tmp_path, capsys, discharge, modulus, start):
    """A 16- or 32-bit ms counter that wraps mid-discharge gives the C of the clean log,
    with a note (was: 'time does not increase ... sort the rows by time')."""
    t, p, _temp, cfg = discharge
    ms = (np.round(t * 1000).astype(np.int64) + start) % modulus
    assert np.any(np.diff(ms) < 0)
    path = _write(tmp_path / "w.csv", "time [ms],pressure [Pa]\n" + "".join(
        f"{a},{b:.1f}\n" for a, b in zip(ms.tolist(), p.tolist(), strict=True)))
    trace = read_csv_trace(path, chunk_bytes=4096)
    np.testing.assert_allclose(np.diff(trace.t), np.diff(t), atol=1e-9)
    assert any(f"wraps at {modulus}" in w for w in trace.source.warnings)
    doc = _analyze(capsys, path, cfg)
    assert _final_c(doc) == pytest.approx(cfg.conductance, rel=0.01)
    assert any("wraps" in w for w in doc["input_warnings"])


def test_a_step_back_that_is_no_wrap_is_refused_without_sorting(tmp_path):
    appended = _write(tmp_path / "a.csv", "time [ms],p [Pa]\n100,7e5\n200,6e5\n300,5e5\n"
                                          "50,5e5\n150,5e5\n")
    with pytest.raises(CsvFormatError, match=r"data row 4.*two records appended") as err:
        read_csv_trace(appended)
    assert "sort" not in str(err.value)
    reversed_ = _write(tmp_path / "r.csv", "time [s],p [Pa]\n3,5e5\n2,6e5\n1,7e5\n0,8e5\n")
    with pytest.raises(CsvFormatError, match="newest first\\? reverse their order") as err:
        read_csv_trace(reversed_)
    assert "sort" not in str(err.value)
    naive = _write(tmp_path / "n.csv", "Timestamp,p [Pa]\n2026-10-25 02:59:59.5,7e5\n"
                                       "2026-10-25 02:00:00.0,6e5\n2026-10-25 02:00:01,6e5\n")
    with pytest.raises(CsvFormatError, match="daylight-saving"):
        read_csv_trace(naive)
    zoned = _write(tmp_path / "z.csv", "Timestamp,p [Pa]\n2026-10-25T02:59:59.5+02:00,7e5\n"
                                       "2026-10-25T02:00:00.0+01:00,6e5\n")
    assert read_csv_trace(zoned).t.tolist() == [0.0, 0.5]  # the zone: no step back


def test_times_of_day_without_a_date_pass_midnight(tmp_path):
    trace = read_csv_trace(_write(tmp_path / "m.csv", "Zeit;Druck [bar]\n23:59:59,5;7\n"
                                                       "00:00:00,0;6\n00:00:00,5;5\n"))
    assert trace.t.tolist() == [0.0, 0.5, 1.0]
    assert any("midnight" in w for w in trace.source.warnings)


# ------------------------------------------------------------------ 5. a torn last row
@pytest.mark.parametrize("encoding", ["utf-8", "utf-16"])
def test_a_torn_last_row_is_left_out_with_a_note(tmp_path, encoding):
    """A file still being written: its last line has no line end and its last number is
    cut (10 for 10.3): left out, with a note (was: read as 10)."""
    path = _write(tmp_path / "t.csv", "time [s],p [kPa]\n0,10.5\n1,10.4\n2,10", encoding)
    trace = read_csv_trace(path)
    assert trace.p.tolist() == [10.5e3, 10.4e3] and trace.source.rows == 2
    (note,) = trace.source.warnings
    assert "no line end" in note and "'2,10'" in note
    whole = _write(tmp_path / "w.csv", "time [s],p [kPa]\n0,10.5\n1,10.4\n2,10.3\n", encoding)
    assert read_csv_trace(whole).source.warnings == ()
    only = _write(tmp_path / "o.csv", "time [s],p [kPa]\n0,10.5", encoding)
    with pytest.raises(CsvFormatError, match=r"no data rows.*without a line end"):
        read_csv_trace(only)


def test_rows_written_after_opening_are_not_read(tmp_path):
    """Every pass reads the rows the file had when opened (a file still growing)."""
    from pneumatic_unload.io.csvlog import CsvStream

    path = _write(tmp_path / "g.csv", "time [s],p [kPa]\n0,10.5\n1,10.4\n2,10")
    stream = CsvStream(path)
    with path.open("a") as fh:
        fh.write(".3\n3,10.2\n")
    first = np.concatenate([c.p for c in stream])
    second = np.concatenate([c.p for c in stream])
    assert first.tolist() == second.tolist() == [10.5e3, 10.4e3]


# ------------------------------------------------------------------ 6. encodings
@pytest.mark.parametrize(("encoding", "bom"), [
    ("utf-16-le", b"\xff\xfe"), ("utf-16-be", b"\xfe\xff"), ("utf-8", b"\xef\xbb\xbf"),
    ("latin-1", b""), ("utf-8", b""), ("utf-16-le", b""), ("utf-32", b""),
])
def test_encodings_are_read(tmp_path, encoding, bom):
    """UTF-16 LE/BE (was: 'no time column found', the header read as 'ÿþt\\x00i...'), UTF-8
    with BOM, latin-1 'T_Gas [°C]', UTF-16 without BOM, UTF-32."""
    text = "time [s],pressure [kPa],T_Gas [°C]\n0,700,25\n0.5,650,24\n1,600,23\n"
    trace = read_csv_trace(_write(tmp_path / "e.csv", text, encoding, bom),
                           chunk_bytes=16)
    assert trace.source.temperature_column == "T_Gas [°C]"
    assert trace.t.tolist() == [0.0, 0.5, 1.0]
    np.testing.assert_allclose(trace.p, [7e5, 6.5e5, 6e5])
    np.testing.assert_allclose(trace.temperature, [298.15, 297.15, 296.15])


def test_cli_reads_a_utf16_logger_file(tmp_path, discharge):
    t, p, temp, cfg = discharge
    text = "Time [s]\tP_Tank [bar]\tT_Gas [°C]\n" + "".join(
        f"{a:.3f}\t{b / 1e5:.6f}\t{g - 273.15:.2f}\n".replace(".", ",")
        for a, b, g in zip(t.tolist(), p.tolist(), temp.tolist(), strict=True))
    path = _write(tmp_path / "u16.csv", text, "utf-16")
    proc = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "analyze",
                           str(path), "--volume", repr(cfg.volume), "--json"],
                          capture_output=True, text=True, cwd=REPO, timeout=300)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert _final_c(doc) == pytest.approx(cfg.conductance, rel=0.01)
    assert doc["inputs"]["initial_temperature"]["source"] == \
        "temperature column at the unload start"


@pytest.mark.parametrize("encoding", ["utf-8", "utf-16"])
def test_a_whole_last_row_without_a_line_end_is_kept(tmp_path, encoding):
    """A finished file that lacks only its final line end (its last row has the shape of the
    row before it) keeps that row and says nothing; a row cut inside a number is left out."""
    path = _write(tmp_path / "w.csv", "time [s],p [kPa]\n0,10.50\n1,9.40\n2,10.31", encoding)
    trace = read_csv_trace(path)
    assert trace.p.tolist() == [10.5e3, 9.4e3, 10.31e3] and trace.source.warnings == ()
    cut = _write(tmp_path / "c.csv", "time [s],p [kPa]\n0,10.50\n1,9.40\n2,10.3", encoding)
    assert read_csv_trace(cut).source.rows == 2
