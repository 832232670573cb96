# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Data-logger CSV input (pneumatic_unload.io.csvlog): real AeroLab file and edge cases."""

from pathlib import Path

import numpy as np
import pytest
from realdata import real_file

from pneumatic_unload.io import (
    CsvFormatError,
    CsvOptionError,
    CsvTrace,
    read_csv_trace,
)

AEROLAB_FILE = "aerolab/orifice_0.094in.csv"
ATM = 101_500.0  # [Pa], within the 101.4-101.6 kPa the rig authors state


def _write(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------ the real AeroLab file


def test_aerolab_file_read_in_place():
    aerolab = real_file(AEROLAB_FILE)
    trace = read_csv_trace(aerolab, gauge=True, atmosphere=ATM)
    assert isinstance(trace, CsvTrace)
    assert trace.t.size == trace.p.size == trace.temperature.size == 242
    assert trace.t[0] == 28.0  # logger clock, not shifted to 0
    assert np.all(np.diff(trace.t) > 0)
    assert trace.p[0] == pytest.approx(439_290.0, abs=1e-6)  # 337.79 kPa gauge + 101500 Pa
    assert trace.temperature[0] == pytest.approx(321.79, abs=1e-9)  # 48.64 C
    src = trace.source
    assert src.path == aerolab and src.rows == 242
    assert (src.time_column, src.pressure_column, src.temperature_column) == (
        "Time [s]",
        "Pressure [kPa]",
        "Temp [C]",
    )
    assert (src.pressure_unit, src.pressure_unit_from) == ("kPa", "header")
    assert (src.temperature_unit, src.temperature_unit_from) == ("C", "header")
    assert (src.gauge, src.gauge_from, src.atmosphere) == (True, "argument", ATM)
    # the transducer's zero offset: the last rows are a little below atmosphere
    assert trace.p[-1] == pytest.approx(ATM - 2930.0, abs=1e-6)
    assert trace.t_ns[0] == 28_000_000_000


def test_aerolab_without_gauge_flag_fails_clearly():
    aerolab = real_file(AEROLAB_FILE)
    with pytest.raises(CsvFormatError, match="gauge=True"):
        read_csv_trace(aerolab)  # gauge readings below 0 would be negative absolute
    with pytest.raises(CsvOptionError, match="atmosphere"):
        read_csv_trace(aerolab, gauge=True)


def test_explicit_unit_matching_header_is_fine_and_contradicting_is_an_error():
    aerolab = real_file(AEROLAB_FILE)
    trace = read_csv_trace(aerolab, pressure_unit="kpa", gauge=True, atmosphere=ATM)
    assert trace.source.pressure_unit_from == "argument"
    assert trace.p[0] == pytest.approx(439_290.0)
    with pytest.raises(CsvOptionError, match="contradicts"):
        read_csv_trace(aerolab, pressure_unit="Pa", gauge=True, atmosphere=ATM)
    with pytest.raises(CsvOptionError, match="contradicts"):
        read_csv_trace(aerolab, temperature_unit="K", gauge=True, atmosphere=ATM)


# --------------------------------------------------------------------- units and columns


@pytest.mark.parametrize(
    ("unit", "scale"),
    [("Pa", 1.0), ("kPa", 1e3), ("bar", 1e5), ("MPa", 1e6), ("psi", 6894.757293168361)],
)
def test_pressure_units_from_argument(tmp_path, unit, scale):
    path = _write(tmp_path, "time,pressure,temperature\n0,2,20\n0.5,1.5,19\n")
    trace = read_csv_trace(path, pressure_unit=unit)
    np.testing.assert_allclose(trace.p, np.array([2.0, 1.5]) * scale, rtol=1e-15)
    assert trace.source.pressure_unit_from == "argument"
    np.testing.assert_allclose(trace.temperature, [293.15, 292.15])  # default C


def test_units_from_header_and_defaults(tmp_path):
    path = _write(tmp_path, "t [ms];p [bar a];T_gas [K]\n0;6;300\n250;5;299\n")
    trace = read_csv_trace(path)
    assert trace.source.delimiter == ";"
    np.testing.assert_allclose(trace.t, [0.0, 0.25])
    np.testing.assert_allclose(trace.p, [6e5, 5e5])
    np.testing.assert_allclose(trace.temperature, [300.0, 299.0])
    assert (trace.source.gauge, trace.source.gauge_from) == (False, "header")
    plain = read_csv_trace(_write(tmp_path, "time,pressure\n0,100000\n1,99000\n", "b.csv"))
    assert plain.temperature is None
    assert plain.source.pressure_unit_from == "default" and plain.source.pressure_unit == "Pa"
    assert plain.source.temperature_unit is None


def test_gauge_marker_in_header(tmp_path):
    path = _write(tmp_path, "Time [s],Pressure [psig]\n0,10\n1,5\n")
    with pytest.raises(CsvOptionError, match="atmosphere"):
        read_csv_trace(path)
    trace = read_csv_trace(path, atmosphere=101_325.0)
    assert trace.source.gauge_from == "header"
    np.testing.assert_allclose(trace.p, 101_325.0 + np.array([10.0, 5.0]) * 6894.757293168361)
    with pytest.raises(CsvOptionError, match="contradicts"):
        read_csv_trace(path, gauge=False)


def test_atmosphere_is_ignored_for_absolute_pressure(tmp_path):
    path = _write(tmp_path, "time,pressure\n0,200000\n1,150000\n")
    trace = read_csv_trace(path, atmosphere=101_325.0)
    np.testing.assert_array_equal(trace.p, [200_000.0, 150_000.0])
    assert trace.source.gauge is False and trace.source.atmosphere is None


def test_explicit_columns_by_name_or_full_header(tmp_path):
    text = "idx,clock [s],P1 [kPa],P2 [kPa],gas [C]\n1,0,500,400,20\n2,1,450,380,19\n"
    path = _write(tmp_path, text)
    with pytest.raises(CsvFormatError, match="pass time_column"):
        read_csv_trace(path)
    trace = read_csv_trace(
        path, time_column="clock", pressure_column="P2 [kPa]", temperature_column="gas"
    )
    np.testing.assert_allclose(trace.p, [400e3, 380e3])
    np.testing.assert_allclose(trace.temperature, [293.15, 292.15])
    assert trace.source.pressure_column == "P2 [kPa]"


def test_ambiguous_columns_are_listed(tmp_path):
    path = _write(tmp_path, "time,pressure up [kPa],pressure tank [kPa]\n0,1,2\n")
    with pytest.raises(CsvFormatError, match="several columns look like pressure") as err:
        read_csv_trace(path)
    assert "'pressure up [kPa]'" in str(err.value) and "'pressure tank [kPa]'" in str(err.value)


# -------------------------------------------------------------------------------- errors


def test_missing_column_lists_available(tmp_path):
    path = _write(tmp_path, "time,volts\n0,1\n")
    with pytest.raises(CsvFormatError, match="no pressure column") as err:
        read_csv_trace(path)
    assert "'time', 'volts'" in str(err.value)
    with pytest.raises(CsvFormatError, match="no column 'temp'"):
        read_csv_trace(path, pressure_column="volts", temperature_column="temp")


def test_non_numeric_cell_names_line_and_column(tmp_path):
    path = _write(tmp_path, "# logger v1\ntime,pressure\n0,100000\n1,oops\n")
    with pytest.raises(CsvFormatError, match=r"log\.csv:4 \(data row 2\).*'oops'.*'pressure'"):
        read_csv_trace(path)
    path = _write(tmp_path, "time,pressure\n0,\n", "e.csv")
    with pytest.raises(CsvFormatError, match="every cell of the pressure column"):
        read_csv_trace(path)
    path = _write(tmp_path, "time,pressure\n0,100000\n,100000\n", "t.csv")
    with pytest.raises(CsvFormatError, match=r"empty cell.*'time'"):
        read_csv_trace(path)
    path = _write(tmp_path, "time,pressure\n0,nan\n", "n.csv")
    with pytest.raises(CsvFormatError, match="non-finite"):
        read_csv_trace(path)


def test_empty_and_header_only_files(tmp_path):
    with pytest.raises(CsvFormatError, match="empty"):
        read_csv_trace(_write(tmp_path, ""))
    with pytest.raises(CsvFormatError, match="empty"):
        read_csv_trace(_write(tmp_path, "\n# only a comment\n\n", "c.csv"))
    with pytest.raises(CsvFormatError, match="no data rows"):
        read_csv_trace(_write(tmp_path, "time,pressure\n", "h.csv"))
    with pytest.raises(CsvFormatError, match="does not exist"):
        read_csv_trace(tmp_path / "missing.csv")


def test_time_must_increase_and_units_must_be_known(tmp_path):
    with pytest.raises(CsvFormatError, match="does not increase at data row 3"):
        read_csv_trace(_write(tmp_path, "time,pressure\n0,1e5\n1,1e5\n1,1e5\n"))
    with pytest.raises(CsvFormatError, match="not a known pressure unit"):
        read_csv_trace(_write(tmp_path, "time,pressure [atm]\n0,1\n", "u.csv"))
    with pytest.raises(CsvOptionError, match="not one of"):
        read_csv_trace(_write(tmp_path, "time,pressure\n0,1\n", "v.csv"), pressure_unit="torr")
    with pytest.raises(CsvFormatError, match="wrong temperature_unit"):
        read_csv_trace(_write(tmp_path, "time,pressure,temp [K]\n0,1e5,-3\n", "k.csv"))


def test_header_with_a_lone_carriage_return_is_a_format_error(tmp_path):
    """(bench_fuzz: the csv module's own Error escaped from the header line.)"""
    path = tmp_path / "cr.csv"
    path.write_bytes(b"\x00\x93\xean;\rv\xc6\xc9")
    with pytest.raises(CsvFormatError, match=r"header \(line 1\) cannot be split"):
        read_csv_trace(path)


# ------------------------------------------------------- multi-rate logs and column names
def test_units_after_an_underscore_are_the_column_units(tmp_path):
    """'pressure_kPa', 'time_ms', 'gas_temperature_c': the unit written as loggers do; a
    short name such as 'p_atm' is not split."""
    path = _write(tmp_path, "time_ms,pressure_kPa,gas_temperature_c,p_atm\n"
                            "0,700,25,101\n10,690,24.9,101\n")
    trace = read_csv_trace(path)
    assert trace.t.tolist() == [0.0, 0.01] and trace.p[0] == pytest.approx(7e5)
    assert trace.temperature[0] == pytest.approx(298.15)
    src = trace.source
    assert (src.time_column, src.pressure_column, src.temperature_column) == (
        "time_ms", "pressure_kPa", "gas_temperature_c")
    assert not src.warnings


def test_a_wall_or_room_temperature_is_not_the_gas_temperature(tmp_path):
    path = _write(tmp_path, "time [s],pressure [kPa],wall temperature [C],T_tank [C]\n"
                            "0,700,20,25\n1,600,20,22\n")
    assert read_csv_trace(path).temperature is None  # no gas-temperature name
    trace = read_csv_trace(path, temperature_column="T_tank")
    assert trace.temperature.tolist() == pytest.approx([298.15, 295.15])


def _multirate_csv(tmp_path, every=50):
    """A 500 Hz pressure log with the gas temperature every ``every``-th row (empty cells
    between, as multi-rate loggers write) and some temperature-only rows; the rig: a hot
    start (T10 303 K, wall 293 K)."""
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.model import simulate

    cfg = RigConfig(volume=5e-3, conductance=8e-9, initial_pressure=6e5, pre_time=1.0,
                    duration=12.0, effects=("heat_transfer",), rate=500.0,
                    initial_temperature=303.15, wall_temperature=293.15, seed=3)
    sim = simulate(cfg)
    rows = ["time_s,pressure_kPa,gas temperature [C]"]
    for k, (t, p, temp) in enumerate(zip(sim.t, sim.measured, sim.temperature,
                                         strict=True)):
        rows.append(f"{t:.4f},{p / 1e3:.4f},{temp - 273.15:.3f}" if k % every == 0
                    else f"{t:.4f},{p / 1e3:.4f},")
        if k % (4 * every) == 7:  # the temperature logger's own instant, no pressure
            rows.append(f"{t + 1e-4:.4f},,{temp - 273.15:.3f}")
    return cfg, _write(tmp_path, "\n".join(rows) + "\n", "multirate.csv")


def test_a_multirate_log_is_read_with_its_empty_cells(tmp_path):
    _cfg, path = _multirate_csv(tmp_path)
    trace = read_csv_trace(path)
    ok_p, ok_t = np.isfinite(trace.p), np.isfinite(trace.temperature)
    assert 0 < np.count_nonzero(~ok_p) < 0.01 * trace.p.size
    assert np.count_nonzero(ok_t) == pytest.approx(trace.t.size / 40, rel=0.2)
    assert trace.temperature[ok_t][0] == pytest.approx(303.15, abs=1.0)  # T10, then cooling
    assert np.all(trace.temperature[ok_t] > 200.0)


def test_a_multirate_log_gives_c_with_t10_from_its_temperature_column(tmp_path, capsys):
    """The CLI analyses the pressure channel and takes T10 from the slower temperature
    channel at the unload start (was refused: 'an empty cell in column ...')."""
    import json

    from pneumatic_unload.app.cli import main

    cfg, path = _multirate_csv(tmp_path)
    assert main(["analyze", str(path), "--volume", "0.005", "--atmosphere", "101325",
                 "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    t10 = d["inputs"]["initial_temperature"]
    assert t10["source"] == "temperature column at the unload start"
    assert t10["value"] == pytest.approx(cfg.initial_temperature, abs=0.5)
    (u,) = [x for x in d["unloads"] if x["final"]]
    assert abs(u["conductance_model"] - cfg.conductance) <= 3 * u["conductance_model_std"]
    assert u["conductance_model"] == pytest.approx(cfg.conductance, rel=0.01)
