# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The ``pneumatic-unload`` command line: analyze (bags, CSV, real data), simulate, errors."""

import json
import math
import subprocess
import sys

import pytest
from realdata import aerolab_args, aerolab_json, real_file

from pneumatic_unload.app.cli import main
from pneumatic_unload.io.bag import read_estimates
from pneumatic_unload.physics import ideal_nozzle_conductance

RULE_OF_THUMB = {"orifice_0.094in.csv": 0.73e-8, "orifice_0.125in.csv": 1.29e-8}


def _run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("name", sorted(RULE_OF_THUMB))
def test_analyze_real_aerolab_csv_within_30_percent(name):
    data = aerolab_json(name)
    u = data["unloads"][0]
    for key in ("conductance", "conductance_model", "conductance_model_std",
                "critical_ratio", "tau_exp", "p10", "p_atm", "p_star", "t_start", "t_cross",
                "status"):
        assert key in u
    ref = RULE_OF_THUMB[name]
    assert u["conductance"] == pytest.approx(ref, rel=0.3)
    assert u["conductance_model"] == pytest.approx(ref, rel=0.3)
    # the gas starts 28-34 K above a room's 20 C (hot from the charge), the wall is not
    # given: the budget's wall line says whether the wall was fitted (a hot start: in the
    # fit's line) or assumed = T10 with an uncertainty that reaches the room
    (wall,) = [x for x in u["budget"]["terms"] if x["name"] == "wall temperature"]
    if u["heat_law"].endswith("+wall"):
        assert wall["std"] == 0.0 and "fitted" in wall["note"]
    else:
        assert "assumed = T10" in wall["note"] and "dC/dTw" in wall["note"]
        assert wall["input_std"] >= (u["initial_temperature"] - 293.15) / 3**0.5 - 1e-9


def test_real_aerolab_text_and_json_tell_b_and_m_alike(capsys):
    """The 0.094 in run fits m (0.31 +- 0.05) while b's 1-sigma is above what a b report
    takes: the text gives m and the reason b is not given, with the fit's value, as the
    JSON does (the text said "b, m = not identifiable" with m in the JSON)."""
    (u,) = [x for x in aerolab_json("orifice_0.094in.csv")["unloads"] if x["final"]]
    code, text, _ = _run(capsys, "analyze", str(real_file("aerolab/orifice_0.094in.csv")),
                         *aerolab_args("orifice_0.094in.csv"))
    assert code == 0
    if u["critical_ratio"] is None:
        assert u["critical_ratio_source"].startswith("not determined: the fit's ")
        assert f"b              = {u['critical_ratio_source']}" in text
    else:
        assert u["critical_ratio_source"] == ""
        assert f"b              = {u['critical_ratio']:.3f}" in text
    assert u["subsonic_index"] is not None
    assert f"m              = {u['subsonic_index']:.3f}" in text
    assert "b, m" not in text


def test_real_aerolab_log_used_within_the_probes_accuracy():
    """The 0.125 in run's log: fitted jointly, the model's gas is 0.61 K rms from it,
    more than twice the channel's noise (0.2 K) but within a probe's accuracy (1 K), with
    the pressure's residual kept (652 Pa rms against 626 alone, Ljung-Box p 7e-11 against
    2.7e-12). It was refused as departing (9.7 K rms after a 53 s lag and a -24 K offset
    fitted to the pressure fit's gas); now it is used, and the status says how."""
    (u,) = [x for x in aerolab_json("orifice_0.125in.csv")["unloads"] if x["final"]]
    g = u["gas_temperature"]
    assert g["used"] and not g["follows"], g
    assert g["rms"] <= g["probe"] == 1.0
    assert "within the probe's accuracy" in u["status_text"]


def test_real_aerolab_log_refused_for_the_pressure_is_a_reading_within_cs_sigma():
    """The 0.094 in run's log: fitted jointly, the model's gas follows it to 0.66 K (within
    the probe's 1 K), but the pressure's residual grows from 562 to 723 Pa rms (Ljung-Box p
    4e-17 -> 3e-94), so it is not used; that reading's C, 9.14e-9 against the pressure's
    8.35e-9, was 3.0 sigma away (the departure's line, C rms / (2 T10), 0.5 %). It is now
    the gas temperature's line (gap / sqrt(3)): the reading within 2 sigma."""
    (u,) = [x for x in aerolab_json("orifice_0.094in.csv")["unloads"] if x["final"]]
    g = u["gas_temperature"]
    assert not g["used"] and "not used: fitted jointly" in g["why"], g
    (line,) = [x for x in u["budget"]["terms"] if "the log departs" in x["name"]]
    assert "joint fit's reading" in line["note"], line
    joint = float(line["note"].split("reading ")[1].split()[0])
    gap = abs(joint - u["conductance_model"])
    assert gap > 0.05 * u["conductance_model"]  # the two readings are far apart
    assert line["std"] == pytest.approx(gap / 3**0.5, rel=0.01)  # (the note's 4 digits)
    assert gap <= 2.0 * u["conductance_model_std"]


#: The AeroLab orifices' diameters [m] (0.094 in and 0.125 in).
DIAMETER = {"orifice_0.094in.csv": 0.094 * 0.0254, "orifice_0.125in.csv": 0.125 * 0.0254}


def test_real_aerolab_orifices_have_one_discharge_coefficient():
    """Two sharp orifices of one rig (0.094 in, 0.125 in): their discharge coefficients C /
    C_ideal(area) agree within twice their combined sigma (issue "The component as ISO
    6358-1:2013 describes it" asks whether they agree within it; two consistent estimates
    do so 68 % of the time, within twice 95 %). Measured: 0.958 +- 0.017 and 1.024 +- 0.099
    (0.66 combined sigma apart) with the pressure alone; since the 0.125 in run's log is
    used (the model's gas 0.61 K rms from it, within the probe's 1 K: its wall's line
    shrinks), 0.960 +- 0.019 and 1.018 +- 0.045 (1.2 combined sigma apart). When the whole
    law family was fitted with a zero offset (6a347df), the 0.094 in run's end, a step to
    -2.4 kPa after its tail had settled at +0.5 kPa, read as an offset of -3861 Pa: 0.917
    +- 0.016, 2.1 combined sigma apart (CI failed here). Since the tail ends before that
    step (estimation/endstep.py), 0.936 +- 0.030 and 1.015 +- 0.027: 1.96 combined sigma
    apart, within twice, not within once. Since the 0.094 in run's joint reading (the log
    followed to 0.66 K, C 9.14e-9) is in its sigma, 0.936 +- 0.059: 1.2 apart. Both lie
    above a sharp orifice's 0.6-0.85, so the
    rig's stated 0.125 m^3 (the authors' figure) is likely high, which moves both alike
    (C ~ V)."""
    cd = {}
    for name, d in DIAMETER.items():
        (u,) = [x for x in aerolab_json(name)["unloads"] if x["final"]]
        ideal = ideal_nozzle_conductance(math.pi * d * d / 4.0)
        cd[name] = (u["conductance_model"] / ideal, u["conductance_model_std"] / ideal)
    (a, sa), (b, sb) = cd.values()
    assert 0.5 < a < 1.2 and 0.5 < b < 1.2, cd
    assert abs(a - b) <= 2.0 * math.hypot(sa, sb), cd


def test_simulate_then_analyze_reproduces_recorded_estimates(tmp_path, capsys):
    bag = tmp_path / "run"
    code, _, err = _run(capsys, "simulate", "--out", str(bag), "--volume", "0.001",
                        "--conductance", "5e-9", "--effects", "heat_transfer", "--seed", "3")
    assert code == 0, err
    code, out, err = _run(capsys, "analyze", str(bag), "--json")
    assert code == 0, err
    published = json.loads(out)["published"]
    recorded = read_estimates(bag)
    assert len(recorded) == len(published) >= 2
    for rec, pub in zip(recorded, published, strict=True):
        for key in ("conductance", "conductance_model", "tau_exp"):  # the same machine
            assert rec[key] == pub[key], key
    assert json.loads(out)["unloads"][0]["conductance_model"] == pytest.approx(5e-9, rel=0.02)


def test_unreadable_input_exits_nonzero_with_one_line(tmp_path):
    bad = tmp_path / "junk.mcap"
    bad.write_bytes(b"not a bag at all")
    proc = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "analyze", str(bad),
                           "--volume", "0.001"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "error" in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "analyze",
                           str(tmp_path / "missing.csv"), "--volume", "0.001"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "no such file" in proc.stderr


def test_analyze_text_says_an_unknown_uncertainty_in_words():
    # issue "Words, not numbers": a NaN or infinite sigma was printed as '+- nan' / '+- inf'
    import math

    from pneumatic_unload.analysis.output import format_result
    from pneumatic_unload.estimation import UnloadResult

    r = UnloadResult(index=0, status="ok", status_text="ok", t_start=0.0, t_cross=0.5,
                     tau_exp=0.5, tau_exp_std=math.nan, p10=7e5, p_atm=101325.0,
                     p_star=3e5, initial_temperature=293.15, volume=1e-3,
                     conductance=8e-9, conductance_model=8.1e-9,
                     conductance_model_std=math.inf, critical_ratio=0.45,
                     critical_ratio_std=math.nan, final=True)
    text = format_result(r)
    assert "nan" not in text and "inf" not in text, text
    assert "tau_exp        = 0.500000 s  (uncertainty not known)" in text
    assert "C (model)      = 8.100e-09 m^3/(s Pa) (uncertainty not known) = 0.8100" in text
    assert "b              = 0.450 (uncertainty not known)" in text
    assert "REPORT C       = 8.100e-09 m^3/(s Pa) (uncertainty not known) = 0.8100" in text
    r.conductance_model_std, r.critical_ratio_std, r.tau_exp_std = 2e-11, 0.01, 0.001
    text = format_result(r)
    assert "C (model)      = 8.100e-09 +- 2.0e-11 m^3/(s Pa) = 0.8100 +- 0.0020 " in text
    assert "b              = 0.450 +- 0.010" in text and "(+- 0.001 s)" in text
    assert "REPORT C       = 8.100e-09 +- 4.0e-11 m^3/(s Pa) (k = 2) = 0.8100 +- 0.0040 " in text


def test_text_output_prints_c_with_four_significant_digits_in_si_and_dm3():
    """C 3e-9 m^3/(s Pa) was printed '3e-09' (one significant digit, trailing zeros
    dropped by :g): every C of the text output has four in SI and in dm^3/(s bar)."""
    import math

    from pneumatic_unload.analysis.output import c_dm3, c_si, format_result
    from pneumatic_unload.estimation import UnloadResult

    assert (c_si(3e-9), c_dm3(3e-9)) == ("3.000e-09", "0.3000")
    assert (c_si(3.0123e-9), c_dm3(3.0123e-9)) == ("3.012e-09", "0.3012")
    assert (c_dm3(8.3e-10), c_dm3(1.234e-7), c_dm3(math.nan)) == ("0.08300", "12.34", "n/a")
    r = UnloadResult(index=0, status="ok", status_text="ok", t_start=0.0, t_cross=0.5,
                     tau_exp=0.5, tau_exp_std=0.001, p10=7e5, p_atm=101325.0,
                     p_star=3e5, initial_temperature=293.15, volume=1e-3,
                     conductance=3e-9, conductance_model=3e-9,
                     conductance_model_std=2.1e-11, final=True)
    text = format_result(r)
    assert "C (eq 39)      = 3.000e-09 m^3/(s Pa) = 0.3000 dm^3/(s bar)" in text, text
    assert "C (model)      = 3.000e-09 +- 2.1e-11 m^3/(s Pa) = 0.3000 +- 0.0021 dm^3/(s bar)" \
        in text, text
    assert "REPORT C       = 3.000e-09 +- 4.2e-11 m^3/(s Pa) (k = 2) = 0.3000 +- 0.0042 " \
        "dm^3/(s bar)" in text, text
    assert "3e-09" not in text


def test_batch_parts_table_and_demo_print_c_with_four_significant_digits():
    from pneumatic_unload.app.batch_cli import parts_text
    from pneumatic_unload.app.demo import _fmt

    part = {"part_id": "V14-1", "part_type": "g14", "n": 2, "conductance_mean": 3e-9,
            "conductance_std": 1.2e-12, "verdict": "pass", "verdict_reason": ""}
    row = parts_text([part]).splitlines()[-1].split()
    assert row[3:5] == ["0.3000", "0.00012"], row
    est = {"conductance": 3.1e-9, "conductance_model": 3e-9, "conductance_model_std": 2e-11,
           "critical_ratio": 0.4, "tau_exp": 0.5, "method": "eq39"}
    line = _fmt(est)
    assert "C (eq 39) = 0.3100 " in line and "model C = 3.000e-09 +- 2.0e-11 m^3/(s Pa) = " \
        "0.3000 +- 0.0020 dm^3/(s bar)" in line, line


def test_analyze_does_not_load_the_test_line(tmp_path):
    """``analyze`` builds every subcommand's parser but loads only what it runs: not the
    test line's SQLAlchemy, Dask or the report (SQLAlchemy alone took 0.11 s of the 0.74 s
    of bench_engine's ``analyze BAG --json``, whose target is half a raw iteration of the
    bag: 0.51 before, 0.40-0.42 without it). In a fresh interpreter: the suite's own has
    them all loaded."""
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.model import simulate

    sim = simulate(RigConfig(volume=1e-3, conductance=5e-9, pre_time=0.3, duration=1.5,
                             rate=200.0, noise_std=300.0, seed=2))
    path = tmp_path / "run.csv"
    rows = ["time,pressure"] + [f"{a:.5f},{b:.2f}" for a, b in zip(sim.t, sim.measured,
                                                                    strict=True)]
    path.write_text("\n".join(rows) + "\n")
    code = (
        "import contextlib, io, json, sys\n"
        "from pneumatic_unload.app.cli import main\n"
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out):\n"
        f"    rc = main(['analyze', {str(path)!r}, '--volume', '0.001', '--json'])\n"
        "heavy = sorted({m.split('.')[0] for m in sys.modules} & {'sqlalchemy', 'dask', "
        "'distributed', 'alembic', 'psycopg', 'jinja2'})\n"
        "slow = [m for m in ('scipy.optimize', 'scipy.signal') if m in sys.modules]\n"
        "print(json.dumps({'rc': rc, 'heavy': heavy, 'slow': slow, 'testline': any("
        "m.startswith('pneumatic_unload.testline') for m in sys.modules), "
        "'n': len(json.loads(out.getvalue())['unloads'])}))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    res = json.loads(done.stdout.strip().splitlines()[-1])
    assert res["rc"] == 0 and res["n"] >= 1
    assert res["heavy"] == [] and not res["testline"], res
    # scipy.optimize cost analyze 0.3 s of import on bench_engine's bag (0.50 -> 0.66 of a
    # raw bag iteration): the flow curve's reduction runs on the package's own engine
    assert res["slow"] == [], res


def test_demo_reads_the_samples_the_live_estimator_missed():
    """The demo explains a live = offline gap by the samples the estimator node counted
    missing (its stats line at shutdown), and finds none where the line is absent."""
    from pneumatic_unload.app.demo import _samples_missed

    log = '[INFO] [estimator]: stats {"received": 7454, "rejected": 0, "missing": 546}\n'
    assert _samples_missed(log) == 546
    assert _samples_missed("[INFO] [estimator]: unload 0 (final)") == 0
