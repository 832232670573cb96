# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Discrepancy workflow (issue #5): fast CI subset of the acceptance harness.

The full randomised harness is ``bench/bench_discrepancy.py``. Here: the building blocks
(fast integrator parity, noise model, prewhitened likelihood, Ljung-Box), null data with
white and AR(1) noise, clear single effects named right, the L/D factor, the multi-run law,
the CLI (JSON fields, report files, exit codes) and the real AeroLab data end to end.
"""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from realdata import aerolab_args

from pneumatic_unload.app.cli import main
from pneumatic_unload.config import RigConfig
from pneumatic_unload.discrepancy import (
    DiscrepancyError,
    DiscrepancySettings,
    find_discrepancy,
    find_discrepancy_runs,
)
from pneumatic_unload.discrepancy.multirun import fit_geometry_law
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.synthetic import draw_case
from pneumatic_unload.fit.likelihood import BinnedLikelihood, make_bins
from pneumatic_unload.fit.noise import (
    NoiseModel,
    combine_sigma2,
    estimate_noise,
    highpass_noise,
    ljung_box,
)
from pneumatic_unload.model import integrate, simulate

REAL = Path(__file__).resolve().parents[3] / "shared" / "real-data" / "aerolab"
V = 2e-3
C = 2e-8  # tau_exp about 0.6 s: short traces (about 4000 samples) keep the tests fast
T10 = 293.15


def _rig(**kw):
    base = {"volume": V, "conductance": C, "critical_ratio": 0.4, "initial_pressure": 7e5,
            "initial_temperature": T10, "wall_temperature": T10, "rate": 1000.0,
            "pre_time": 0.2, "noise_std": 1000.0, "seed": 11}
    base.update(kw)
    return RigConfig(**base)


def _run(cfg, **kw):
    sim = simulate(cfg)
    s = DiscrepancySettings(volume=cfg.volume, initial_temperature=cfg.initial_temperature,
                            atmosphere=cfg.atmosphere, **kw)
    return find_discrepancy(sim.t, sim.measured, s)


# ----------------------------------------------------------------------- building blocks
@pytest.mark.parametrize("effects,extra", [
    (("valve_opening",), {"valve_opening_time": 0.03}),
    (("pipe_volume", "leak"), {"pipe_volume": 4e-4, "pipe_conductance": 6e-8}),
    (("heat_transfer",), {"heat_transfer_mode": "fixed", "heat_transfer_coefficient": 2.0}),
])
def test_integrator_output_does_not_depend_on_the_output_grid(effects, extra):
    """One integrator, segmented at the valve events: the states at a coarse set of instants
    (what the binned likelihood asks for) equal those on the full sample grid."""
    cfg = _rig(effects=effects, **extra)
    t = np.arange(0.0, 3.0, 1e-3)
    full = integrate(cfg, t, 0.2)
    idx = np.unique(np.concatenate(([0], np.arange(0, t.size, 97), [t.size - 1])))
    coarse = integrate(cfg, t[idx], 0.2)
    assert np.max(np.abs(coarse[:, 0] - full[idx, 0])) < 1e-5 * cfg.initial_pressure
    assert np.max(np.abs(coarse[:, 1] - full[idx, 1])) < 1e-5 * T10


def test_noise_model_recovers_sigma_and_rho_from_plateaus():
    cfg = _rig(noise_std=0.0, noise_ar_std=800.0, noise_ar_rho=0.7, seed=5)
    sim = simulate(cfg)
    nm = estimate_noise(sim.t, sim.measured, 0.2, 0.6)
    assert nm.source == "plateaus"
    assert nm.sigma == pytest.approx(800.0, rel=0.15)
    assert nm.rho == pytest.approx(0.7, abs=0.08)


def _ar1(n, rho, sigma, seed):
    rng = np.random.default_rng(seed)
    e = np.empty(n)
    e[0] = rng.normal(0, sigma)
    u = rng.normal(0, sigma * math.sqrt(1 - rho * rho), n)
    for k in range(1, n):
        e[k] = rho * e[k - 1] + u[k]
    return e


#: Harness draws with short traces (2000-6300 samples; the issue's 1010 among them).
SHORT_DRAWS = (1002, 1007, 1010, 1014, 1017, 1018, 1021, 1022, 1023)


def test_sigma_tracks_the_realised_noise_on_short_traces():
    """Harness case 1010 (2092 samples): the plateaus (908 samples) alone gave sigma
    944 Pa while the noise realised on the trace is 981 Pa rms, so even a perfect model
    read a normalised RMS of 1.039 (> NRMS_LIMIT, 1.02); the whole-trace high-pass
    estimate fixes that. Over the short draws: sigma within the statistical uncertainty of
    an rms of the trace's n samples, 1/sqrt(2 n), of the realised noise (each within 3 of
    it; their mean square at most 1: measured 0.11) and without bias (mean +0.09 %, its
    standard error 0.13 %), so that a perfect model's normalised RMS stays within
    NRMS_LIMIT; and nearer to it than the plateaus alone, about 40 % of the samples (rms
    relative errors measured 0.4 % against 1.8 %)."""
    from pneumatic_unload.discrepancy.types import NRMS_LIMIT

    err, err_plateau, z = [], [], []
    for seed in SHORT_DRAWS:
        case = draw_case("pipe_volume", seed)
        sim, clean = case.simulate(), case.noise_free()
        prob = Problem(sim.t, sim.measured, DiscrepancySettings(volume=case.config.volume))
        n = prob.t.size
        realised = float(np.sqrt(np.mean((sim.measured - clean.measured)[:n] ** 2)))
        nm = prob.noise
        assert nm.source == "plateaus" and nm.highpass_weight > 0.8, (seed, nm)
        u = 1.0 / math.sqrt(2.0 * n)  # relative 1-sigma of an rms of n samples
        err.append(nm.sigma / realised - 1.0)
        err_plateau.append(nm.sigma_plateau / realised - 1.0)
        z.append(err[-1] / u)
        assert abs(z[-1]) < 3.0, (seed, err[-1], u)
        assert abs(nm.sigma_highpass / realised - 1.0) < 3.0 * u, seed
        assert 1.0 / NRMS_LIMIT < realised / nm.sigma < NRMS_LIMIT, seed
    assert float(np.mean(np.square(z))) <= 1.0, z
    # no bias: the mean relative error within 3 standard errors of zero (a t test)
    assert abs(float(np.mean(err))) < 3.0 * float(np.std(err, ddof=1)) / math.sqrt(len(err))
    rms, rms_plateau = (float(np.sqrt(np.mean(np.square(e)))) for e in (err, err_plateau))
    assert rms < 0.5 * rms_plateau, (rms, rms_plateau)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9])
def test_highpass_noise_is_unbiased_under_ar1_and_ignores_kinks_and_spikes(rho):
    n, sigma = 40000, 1000.0
    e = _ar1(n, rho, sigma, seed=7)
    k = np.arange(n)
    signal = 7e5 * np.exp(-np.clip(k - 5000, 0, None) / 3000.0)  # kink at k = 5000
    y = signal + e
    y[20000] += 50 * sigma  # a spike: its window is an outlier
    hp = highpass_noise(y, rho, 5000)
    assert hp is not None
    assert math.sqrt(hp.variance) == pytest.approx(float(np.std(e)), rel=0.03)
    # the estimate leans on rho the more, the more correlated the noise
    assert abs(hp.dlog_drho) < 0.3 if rho == 0.0 else abs(hp.dlog_drho) > 0.4


def test_plateau_estimate_takes_over_with_strongly_correlated_noise():
    n = 5000
    n_plateau = 2000  # about 40 % of a short trace lies on the plateaus
    weights = {}
    for rho in (0.0, 0.9):
        hp = highpass_noise(_ar1(n, rho, 1000.0, seed=3), rho, 0)
        assert hp is not None
        weights[rho] = combine_sigma2(1e6, n_plateau, rho, hp)[1]
    assert weights[0.0] > 0.8  # white: the whole trace, which holds the plateaus, wins
    assert weights[0.9] < 0.6  # rho 0.9: the high-pass estimate hinges on rho
    hp = highpass_noise(_ar1(n, 0.0, 1000.0, seed=3), 0.0, 0)
    assert hp is not None
    s2, w = combine_sigma2(4e6, n_plateau, 0.0, hp)
    assert s2 == pytest.approx(w * hp.variance + (1 - w) * 4e6)


def test_prewhitened_likelihood_is_chi2_under_ar1_noise_and_naive_one_is_not():
    rng = np.random.default_rng(3)
    n, rho, sigma = 20000, 0.9, 1000.0
    e = np.empty(n)
    e[0] = rng.normal(0, sigma)
    u = rng.normal(0, sigma * math.sqrt(1 - rho * rho), n)
    for k in range(1, n):
        e[k] = rho * e[k - 1] + u[k]
    t = np.arange(n) * 1e-3
    edges = make_bins(t, 1.0)
    ok = BinnedLikelihood(t, e, NoiseModel(sigma, rho, n, "test"), edges)
    naive = BinnedLikelihood(t, e, NoiseModel(sigma, 0.0, n, "test"), edges)
    z_ok, z_naive = ok.residuals(np.zeros(n)), naive.residuals(np.zeros(n))
    assert float(z_ok @ z_ok) / z_ok.size == pytest.approx(1.0, abs=0.15)
    assert float(z_naive @ z_naive) / z_naive.size > 3.0


def test_ljung_box_separates_white_from_structured():
    rng = np.random.default_rng(0)
    white = rng.normal(size=2000)
    assert ljung_box(white)[1] > 0.01
    assert ljung_box(white + np.sin(np.arange(2000) / 50.0))[1] < 1e-6


# ----------------------------------------------------------------------------- decisions
def test_null_dataset_claims_no_effect():
    res = _run(_rig(seed=21))
    assert res.effect == "none" and res.effects == []
    assert res.ambiguous_with == []
    assert max(res.delta_bic.values()) < 10.0
    assert res.after.nrms < 1.05
    assert "no discrepancy" in res.verdict


def test_ar1_null_dataset_claims_no_effect():
    res = _run(_rig(noise_std=0.0, noise_ar_std=1000.0, noise_ar_rho=0.9, seed=4))
    assert res.noise.rho == pytest.approx(0.9, abs=0.05)
    assert res.effect == "none", res.delta_bic


@pytest.mark.parametrize("effect,extra,param,truth", [
    ("heat_transfer", {"heat_transfer_mode": "fixed",
                       "heat_transfer_coefficient": 7e5 * V / (0.4 * T10 * 2.0)},
     "tau_heat", 2.0),
    ("leak", {"leak_coefficient": 0.1 * C * 1.185 * 7e5 / (7e5 - 101325.0)},
     "leak_fraction", 0.1),
    ("sensor_offset", {"sensor_offset": 4000.0}, "offset", 4000.0),
])
def test_clear_effect_is_named_alone_with_its_size(effect, extra, param, truth):
    res = _run(_rig(effects=(effect,), seed=7, **extra))
    assert res.effect == effect, res.delta_bic
    assert res.ambiguous_with == []
    iv = res.parameters[param]
    assert iv.value == pytest.approx(truth, rel=0.1)
    assert iv.low <= truth <= iv.high or abs(iv.value / truth - 1) < 0.03
    assert iv.identifiable
    assert res.rms_after < res.rms_before
    assert res.after.nrms <= 1.05 and res.after.white
    assert res.delta_bic[effect] > 10.0


@pytest.mark.parametrize("m", [0.3, 0.7])
def test_a_subsonic_index_away_from_one_half_is_named_with_its_value(m):
    """The component's ISO 6358-1:2013 m is a candidate: a record whose flow law has m 0.3
    or 0.7 (the baseline holds 0.5) names it, with m within 0.02 and inside its interval
    (measured: 0.304 [0.291, 0.318], 0.700 [0.689, 0.712]); the residual ends white."""
    res = _run(_rig(subsonic_index=m, seed=7))
    assert res.effect == "subsonic_index", res.delta_bic
    iv = res.parameters["m"]
    assert abs(iv.value - m) < 0.02 and iv.low <= m <= iv.high, iv
    assert res.delta_bic["subsonic_index"] > 10.0
    assert res.after.nrms <= 1.05 and res.after.white


def test_valve_opening_is_inside_the_reported_set():
    res = _run(_rig(effects=("valve_opening",), valve_opening_time=0.06, seed=8))
    assert "valve_opening" in [res.effect, *res.ambiguous_with]
    if res.ambiguous_with:
        assert res.extra_data  # says which measurement would separate them


def test_geometry_factor_is_not_identifiable_from_one_trace():
    res = _run(_rig(seed=9), candidates=())
    g = res.geometry_factor
    assert g["identifiable"] is False
    assert g["sensitivity_correlation_with_C"] == pytest.approx(1.0, abs=1e-6)
    # and the law refuses one geometry
    law = fit_geometry_law([2.0, 2.0], [1e-8, 1.01e-8], [1e-10, 1e-10])
    assert not law.identifiable and "two different" in law.reason


def test_several_runs_identify_one_shared_geometry_law():
    c_inf, a = 2.0e-8, 0.25
    lds = [0.6, 1.2, 2.4]
    traces, settings = [], []
    for k, ld in enumerate(lds):
        cfg = _rig(conductance=c_inf * (1 - a / ld), length_diameter_ratio=ld, seed=30 + k)
        sim = simulate(cfg)
        traces.append((sim.t, sim.measured))
        settings.append(DiscrepancySettings(volume=V, length_diameter_ratio=ld,
                                            candidates=()))
    results, law = find_discrepancy_runs(traces, settings)
    assert len(results) == 3 and law.identifiable
    assert law.c_inf == pytest.approx(c_inf, rel=0.01)
    assert law.a == pytest.approx(a, abs=0.02)
    assert abs(law.a - a) < 4 * law.a_std + 1e-3


def test_bad_input_gives_clear_errors():
    s = DiscrepancySettings(volume=V)
    t = np.arange(0.0, 2.0, 1e-3)
    with pytest.raises(DiscrepancyError, match="no complete unload"):
        find_discrepancy(t, np.full(t.size, 7e5) + np.random.default_rng(0).normal(
            0, 100, t.size), s)
    p = np.full(t.size, 7e5)
    p[100] = np.nan
    with pytest.raises(DiscrepancyError, match="non-finite"):
        find_discrepancy(t, p, s)
    with pytest.raises(DiscrepancyError, match="too few"):
        find_discrepancy(t[:5], p[:5], s)
    with pytest.raises(DiscrepancyError, match="unknown candidate"):
        DiscrepancySettings(volume=V, candidates=("magic",))


def _stuck(cfg, offset):
    """Simulated record (t [s], p [Pa]) whose sensor sticks 1 s from t_open + offset [s]."""
    sim = simulate(cfg)
    p = sim.measured.copy()
    i0 = int(np.searchsorted(sim.t, sim.t_open + offset))
    p[i0:i0 + 1000] = p[i0]
    return sim.t, p


@pytest.mark.parametrize("offset", [0.05, 0.3, 0.8])
def test_stuck_sensor_is_the_finding_not_a_fitted_effect(offset):
    # issue 13: fitted as "leak, heat transfer"; before, during and after the p* crossing
    t, p = _stuck(_rig(duration=4.0), offset)
    with pytest.raises(DiscrepancyError, match="bad data, not fitted: sensor stuck at"):
        find_discrepancy(t, p, DiscrepancySettings(volume=V))


def test_cli_stuck_sensor_is_named_in_bounded_time(tmp_path):
    import subprocess
    import sys
    import time

    t, p = _stuck(_rig(duration=4.0), 0.3)
    csv = tmp_path / "stuck.csv"
    csv.write_text("Time [s],Pressure [kPa]\n" + "\n".join(
        f"{a:.4f},{b / 1e3:.4f}" for a, b in zip(t, p, strict=True)) + "\n")
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "discrepancy",
                           str(csv), "--volume", str(V)], capture_output=True, text=True,
                          timeout=120)
    elapsed = time.monotonic() - t0
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "sensor stuck at" in proc.stderr and "leak" not in proc.stderr + proc.stdout
    assert elapsed < 60.0  # refused after the estimator's pass, not after a search


def test_harness_draws_are_reproducible_and_in_range():
    a, b = draw_case("leak", 3), draw_case("leak", 3)
    assert a.config == b.config and a.truth == b.truth
    assert 0.02 <= a.truth["leak_fraction"] <= 0.2
    cfg = draw_case("none", 5, rho=0.5).config
    assert cfg.noise_ar_rho == 0.5 and cfg.noise_std == 0.0 and cfg.effects == ()


# ---------------------------------------------------------------------------------- CLI
def _write_csv(path, cfg):
    sim = simulate(cfg)
    rows = "\n".join(f"{t:.4f},{p / 1e3:.4f}" for t, p in zip(sim.t, sim.measured,
                                                              strict=True))
    path.write_text("Time [s],Pressure [kPa]\n" + rows + "\n")


def test_cli_json_fields_and_report_files(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    _write_csv(csv, _rig(effects=("sensor_offset",), sensor_offset=5000.0, seed=12))
    rep = tmp_path / "report"
    code = main(["discrepancy", str(csv), "--volume", str(V), "--json", "--report", str(rep),
                 "--max-effects", "1"])
    out = capsys.readouterr().out
    assert code == 0
    d = json.loads(out)
    for key in ("effect", "ambiguous_with", "parameters", "rms_before", "rms_after",
                "delta_bic", "noise"):
        assert key in d
    assert d["effect"] == "sensor_offset"
    assert set(d["delta_bic"]) == {"heat_transfer", "valve_opening", "sensor_lag", "leak",
                                   "leak_downstream", "orifice_leak",
                                   "orifice_leak_downstream", "pipe_volume", "sensor_offset",
                                   "sensor_gain", "hot_start", "subsonic_index"}
    assert d["noise"]["sigma"] == pytest.approx(1000.0, rel=0.1) and "rho" in d["noise"]
    off = d["parameters"]["offset"]
    assert off["ci_low"] <= 5000.0 <= off["ci_high"] or abs(off["value"] - 5000) < 150
    assert d["rms_after"] < d["rms_before"]
    md = (rep / "report.md").read_text()
    assert "sensor_offset" in md and "![residuals](residuals.png)" in md
    for png in ("models.png", "residuals.png", "ranking.png", "residual_vs_state.png"):
        assert (rep / png).stat().st_size > 5000


def test_cli_exit_codes(tmp_path, capsys):
    assert main(["discrepancy", str(tmp_path / "missing.csv"), "--volume", "0.001"]) == 2
    flat = tmp_path / "flat.csv"
    flat.write_text("Time [s],Pressure [kPa]\n" + "\n".join(
        f"{k * 1e-3:.3f},{700 + 0.1 * math.sin(k):.4f}" for k in range(500)) + "\n")
    assert main(["discrepancy", str(flat), "--volume", "0.001"]) == 2
    err = capsys.readouterr().err
    assert "no complete unload" in err and len(err.strip().splitlines()) == 2
    with pytest.raises(SystemExit) as exc:
        main(["discrepancy", str(flat), "--max-effects", "7"])
    assert exc.value.code == 2


# ---------------------------------------------------------------------------- real data
def test_real_aerolab_runs_end_to_end(tmp_path, capsys):
    path = REAL / "orifice_0.125in.csv"
    if not path.exists():
        pytest.skip(f"real data not present at {path}")
    rep = tmp_path / "aerolab"
    code = main(["discrepancy", str(path), "--volume", "0.125", "--gauge", "--atmosphere",
                 "101500", "--pressure-unit", "kPa", "--fit-wall-temperature", "--json",
                 "--report", str(rep), "--no-profile", "--max-effects", "2"])
    assert code == 0
    d = json.loads(capsys.readouterr().out)
    # the hot gas cooling on the wall is the dominant missing effect of this rig
    assert d["effect"] == "heat_transfer"
    assert d["rms_after"] < 0.5 * d["rms_before"]
    tc = d["temperature_check"]
    assert tc["available"] and tc["heat_transfer_fitted"]
    assert tc["final"]["rms"] < tc["baseline"]["rms"]
    assert (rep / "temperature.png").exists() and (rep / "report.md").exists()
    # the best reference there is for this rig: the sharp orifice's rule of thumb (0.128
    # d^2 dm^3/(s bar), d = 3.18 mm; the data's README), not a calibration: within 30 %
    assert d["conductance"] == pytest.approx(1.29e-8, rel=0.3)
    # the fitted model still heats the gas back toward a warm wall while the log shows it
    # cooling: flagged, with the wall temperature as the likely culprit (issue 12)
    assert tc["contradicts"] and "wall temperature" in tc["likely_reason"]
    assert "contradicts" in d["verdict"]
    # the range is the models the data allow (several here: the hot gas, the transducer's
    # zero, a leak tell apart badly at 1 Hz); the reference lies within it
    rng = d["conductance_range"]
    assert rng["low"] <= d["conductance"] <= rng["high"], rng
    assert rng["low"] <= 1.29e-8 <= rng["high"], rng


# ------------------------------------------------------------- ambiguity rules (issue 12)
class _Fit:
    """A fitted model as the ambiguity rules see it: effects, C and its sigma, BIC, the
    parameters with their bounds (C, and an effect parameter that may sit at a bound)."""

    def __init__(self, effects, c, s, bic, *, at_bound=False, chi2=None):
        from pneumatic_unload.fit.params import Parameter, Parameters

        self.effects = tuple(effects)
        self.bic = bic
        self.chi2 = bic if chi2 is None else chi2  # chi2 given: more parameters than BIC says
        self._s = s
        x = 1.0 if at_bound else 0.5
        self.theta = {"C": c, "x": x}
        self.result = type("R", (), {"params": Parameters([
            Parameter("C", c, 1e-13, 1e-5, log=True, scale=0.1),
            Parameter("x", x, 0.0, 1.0, scale=0.1)])})()

    def std(self, name):
        return self._s


def _round(base, fits, thr=10.0):
    from pneumatic_unload.discrepancy.search import decide
    from pneumatic_unload.discrepancy.types import Round

    delta, win, amb = decide(base, fits, thr)
    return Round(base_effects=base.effects, base_bic=base.bic, fits=fits, delta_bic=delta,
                 winner=win, ambiguous_with=amb, base=base)


def _diag(white, nrms):
    from pneumatic_unload.discrepancy.types import Diagnostics

    return Diagnostics(rms=nrms, nrms=nrms, ljung_box_p=0.5 if white else 1e-6, white=white,
                       phases={}, corr_pressure=math.nan, corr_rate=math.nan)


def test_ambiguity_rules_each_add_the_competing_C():
    from pneumatic_unload.discrepancy.ambiguity import PARALLEL_LEAK_MAX, conductance_ambiguity

    base = _Fit((), 1.2e-8, 1e-11, 1000.0)
    heat = _Fit(("heat_transfer",), 1.00e-8, 1e-11, 500.0)
    # nothing competes: the range is the final model's 3-sigma interval, and the bound of a
    # parallel leak (which no record can tell from C) is apart, not its lower end
    alone = {"heat_transfer": heat, "pipe_volume": _Fit(("pipe_volume",), 1.1e-8, 1e-11,
                                                        900.0)}
    amb = conductance_ambiguity(base, [_round(base, alone)], heat, 10.0)
    assert not amb.ambiguous
    assert amb.low == pytest.approx(1e-8 - 3e-11) and amb.high == pytest.approx(1e-8 + 3e-11)
    assert amb.parallel_low == pytest.approx((1e-8 - 3e-11) / (1 + PARALLEL_LEAK_MAX))
    # equal fits: within the BIC threshold, C apart by more than the combined sigma
    close = {**alone, "pipe_volume": _Fit(("pipe_volume",), 1.1e-8, 1e-11, 505.0)}
    amb = conductance_ambiguity(base, [_round(base, close)], heat, 10.0)
    assert [m["effects"] for m in amb.members] == [["heat_transfer"], ["pipe_volume"]]
    assert amb.high >= 1.1e-8 and "fits about as well" in amb.members[1]["why"]
    # ... not when their C agree within sigma
    same = {**alone, "pipe_volume": _Fit(("pipe_volume",), 1.00001e-8, 1e-11, 505.0)}
    assert not conductance_ambiguity(base, [_round(base, same)], heat, 10.0).ambiguous
    # ... nor when they differ by a negligible 0.05 % of C, however small the sigmas
    tiny = _Fit(("heat_transfer",), 1.00e-8, 1e-14, 500.0)
    near = {"heat_transfer": tiny, "pipe_volume": _Fit(("pipe_volume",), 1.0005e-8, 1e-14,
                                                       505.0)}
    assert not conductance_ambiguity(base, [_round(base, near)], tiny, 10.0).ambiguous
    # white fits: far behind by BIC, but both white at nRMS <= 1.02
    quality = {id(heat): _diag(True, 1.0), id(alone["pipe_volume"]): _diag(True, 1.01),
               id(base): _diag(False, 3.0)}
    amb = conductance_ambiguity(base, [_round(base, alone)], heat, 10.0,
                                lambda f: quality[id(f)])
    assert amb.ambiguous and "within noise" in amb.members[1]["why"]
    quality[id(alone["pipe_volume"])] = _diag(True, 1.05)
    assert not conductance_ambiguity(base, [_round(base, alone)], heat, 10.0,
                                     lambda f: quality[id(f)]).ambiguous
    # ... nor one no better than its round's base (its C trades along a degenerate valley)
    worse = _Fit(("pipe_volume",), 1.7e-8, 1e-11, 1005.0)
    quality[id(worse)] = _diag(True, 1.0)
    assert not conductance_ambiguity(base, [_round(base, {**alone, "pipe_volume": worse})],
                                     heat, 10.0, lambda f: quality[id(f)]).ambiguous
    # a winner with a parameter at its bound: its runner-up, however far behind
    heat_b = _Fit(("heat_transfer",), 1.00e-8, 1e-11, 500.0, at_bound=True)
    amb = conductance_ambiguity(base, [_round(base, {**alone, "heat_transfer": heat_b})],
                                heat_b, 10.0)
    assert amb.ambiguous and "bound" in amb.members[1]["why"]
    # a placement variant of the same leak as runner-up, however far behind
    up = _Fit(("leak",), 1.0e-8, 1e-11, 500.0)
    down = _Fit(("leak_downstream",), 0.8e-8, 1e-11, 600.0)
    amb = conductance_ambiguity(base, [_round(base, {"leak": up, "leak_downstream": down})],
                                up, 10.0)
    assert amb.ambiguous and amb.low <= 0.8e-8 and "another place or law" in \
        amb.members[1]["why"]
    assert any("valve closed" in x for x in amb.separating)
    # a law variant of the winner fitting as well (chi^2 0.5 lower) but one parameter
    # more (ln n = 10.9): 10.4 behind by BIC, yet the data cannot tell the laws apart
    # (fresh bench seed 101001, where it came third): in the round's set, and a member
    # when its C differs; a look-alike of another physics is judged by its BIC alone
    lam = _Fit(("leak_downstream",), 3.40e-9, 1e-11, 500.0)
    ori = _Fit(("orifice_leak_downstream",), 2.9e-9, 1e-10, 510.4, chi2=499.5)
    r = _round(base, {"leak_downstream": lam, "orifice_leak_downstream": ori,
                      "leak": _Fit(("leak",), 3.41e-9, 1e-11, 501.0),
                      "pipe_volume": _Fit(("pipe_volume",), 6e-9, 1e-11, 510.4, chi2=499.5)})
    assert (r.winner, r.ambiguous_with) == ("leak_downstream",
                                            ["leak", "orifice_leak_downstream"])
    amb = conductance_ambiguity(base, [r], lam, 10.0)
    assert [m["effects"] for m in amb.members] == [["leak_downstream"],
                                                   ["orifice_leak_downstream"]]
    assert "cannot tell" in amb.members[1]["why"] and amb.low <= 2.9e-9 - 3e-10
    # ... not when its fit is worse by more than the threshold (chi^2 12 higher)
    r = _round(base, {"leak_downstream": lam, "orifice_leak_downstream": _Fit(
        ("orifice_leak_downstream",), 2.9e-9, 1e-10, 522.9, chi2=512.0)})
    assert (r.winner, r.ambiguous_with) == ("leak_downstream", [])
    # heat transfer and the hot start are nested, not variants: the BIC decides
    hot = _Fit(("hot_start",), 1.0e-8, 1e-11, 500.0)
    far = _Fit(("heat_transfer",), 1.05e-8, 1e-11, 600.0)
    assert not conductance_ambiguity(
        base, [_round(base, {"hot_start": hot, "heat_transfer": far})], hot, 10.0).ambiguous


# ------------------------------------------------- an extra effect must earn its place
def _base_fit(cfg):
    sim = simulate(cfg)
    prob = Problem(sim.t, sim.measured, DiscrepancySettings(volume=V, atmosphere=101325.0))
    base = prob.fit(prob.model(()), [prob.neutral_theta(0.4)])
    return prob, base


def test_transducer_effect_needs_an_end_level_no_physics_gives():
    from pneumatic_unload.discrepancy.search import end_level_evidence, fit_candidate

    # an offset moves the end level off the stated p_atm: no physics effect can
    prob, base = _base_fit(_rig(effects=("sensor_offset",), sensor_offset=3000.0, seed=7))
    z, what = end_level_evidence(prob, base, {})
    assert z > 20 and "Pa from the baseline" in what
    # heat transfer ends at p_atm: the physics candidate explains the end, so a gain or
    # offset that also fits better than the baseline has no evidence of its own
    prob, base = _base_fit(_rig(effects=("heat_transfer",), heat_transfer_mode="fixed",
                                heat_transfer_coefficient=7e5 * V / (0.4 * T10 * 1.0),
                                seed=3))
    fits = {"heat_transfer": fit_candidate(prob, base, [prob.neutral_theta(0.4)],
                                           "heat_transfer")}
    z, what = end_level_evidence(prob, base, fits)
    assert z < 4 and "heat_transfer" in what


def test_noise_refitted_on_the_residual_of_the_effects_named():
    from pneumatic_unload.discrepancy.search import residual_noise

    prob, base = _base_fit(_rig(effects=("heat_transfer",), heat_transfer_mode="fixed",
                                heat_transfer_coefficient=7e5 * V / (0.4 * T10 * 1.0),
                                seed=3))
    structured = residual_noise(prob, base)  # the baseline misses the heat transfer
    assert structured.noise.sigma > 1.5 * prob.noise.sigma
    assert structured.noise.rho > prob.noise.rho + 0.3
    assert structured.lik.edges is prob.lik.edges or np.array_equal(structured.lik.edges,
                                                                    prob.lik.edges)
    prob0, base0 = _base_fit(_rig(seed=21))  # nothing missing: the noise model stays
    same = residual_noise(prob0, base0)
    assert same.noise.sigma == pytest.approx(prob0.noise.sigma, rel=0.03)
    assert same.noise.rho <= prob0.noise.rho + 0.05


# ------------------------------------------------------------------- hot start (issue 12)
def _hot_rig(**kw):
    """Gas 30 K above the wall at the valve opening, heat exchange tau_heat 1 s."""
    t10 = T10 + 30.0
    return _rig(effects=("heat_transfer",), heat_transfer_mode="fixed",
                heat_transfer_coefficient=7e5 * V / (0.4 * t10 * 1.0),
                initial_temperature=t10, wall_temperature=T10, **kw)


def test_hot_start_is_named_with_the_wall_temperature():
    res = _run(_hot_rig(seed=5), candidates=("heat_transfer", "hot_start"),
               profile=False, max_effects=1)
    assert res.effect == "hot_start", res.delta_bic
    assert res.delta_bic["hot_start"] - res.delta_bic["heat_transfer"] > 10
    assert res.parameters["t_wall"].value == pytest.approx(T10, abs=3.0)
    # C two-sided against the truth within its stated sigma; the range is that interval
    assert abs(res.conductance - C) <= 3.0 * res.conductance_std()
    lo, hi = res.conductance_range
    assert lo <= C <= hi and hi - lo < 0.1 * C


def test_logged_temperature_contradicting_the_model_names_the_wall():
    """The wall assumed at T10 for a gas hot after charging (the AeroLab situation): the
    model heats the gas back toward T10; the log says otherwise, and the verdict says the
    wall temperature is the likely culprit. With the hot start allowed, the log agrees."""
    cfg = _hot_rig(seed=6)
    sim = simulate(cfg)
    temp = (sim.t, sim.temperature)
    kw = {"volume": V, "initial_temperature": cfg.initial_temperature, "profile": False,
          "max_effects": 1}
    res = find_discrepancy(sim.t, sim.measured, DiscrepancySettings(
        candidates=("heat_transfer",), **kw), temperature=temp)
    tc = res.temperature_check
    assert res.effect == "heat_transfer" and tc["contradicts"], tc["summary"]
    assert "wall temperature" in tc["likely_reason"] and "--wall-temperature" in \
        tc["measure_next"]
    assert "contradicts" in res.verdict and any("gas temperature" in x
                                                for x in res.extra_data)
    res = find_discrepancy(sim.t, sim.measured, DiscrepancySettings(
        candidates=("heat_transfer", "hot_start"), **kw), temperature=temp)
    tc = res.temperature_check
    assert res.effect == "hot_start" and not tc["contradicts"] and tc["agrees"], \
        tc["summary"]


def test_nested_extension_and_look_alikes_must_earn_their_place():
    from pneumatic_unload.discrepancy.search import decide, look_alikes

    base = _Fit((), 1e-8, 1e-11, 1000.0)
    # the hot start (one parameter more than heat transfer) within 10 of it: heat transfer
    # is named, alone
    fits = {"heat_transfer": _Fit(("heat_transfer",), 1e-8, 1e-11, 500.0),
            "hot_start": _Fit(("hot_start",), 1e-8, 1e-11, 492.0),
            "pipe_volume": _Fit(("pipe_volume",), 1e-8, 1e-11, 700.0)}
    assert decide(base, fits, 10.0)[1:] == ("heat_transfer", [])
    fits["hot_start"] = _Fit(("hot_start",), 1e-8, 1e-11, 470.0)  # 30 better: named
    assert decide(base, fits, 10.0)[1:] == ("hot_start", [])
    # a refused candidate is neither winner nor ambiguity
    assert decide(base, fits, 10.0, {"hot_start": "no"})[1:] == ("heat_transfer", [])
    # once a leak is named, its other law / place and the round's ambiguity set are not
    # tried on top of it
    rest = ["leak", "orifice_leak", "leak_downstream", "pipe_volume", "sensor_gain",
            "heat_transfer"]
    assert look_alikes("leak", ["sensor_gain"], rest) == [
        "leak", "orifice_leak", "leak_downstream", "sensor_gain"]
    assert look_alikes("heat_transfer", [], ["hot_start", "leak"]) == ["hot_start"]


def test_an_ambiguity_names_none_of_its_members_and_advises_only_the_separation():
    """Two candidates within the BIC threshold (a downstream leak and a pipe volume fit a
    pipe-volume trace alike): the verdict names neither (``named`` empty) although the best
    stands for the set in the final model, and 'What to do next' gives the measurement that
    separates them, not the repair of either; a later round's clear winner is named."""
    from types import SimpleNamespace

    from pneumatic_unload.discrepancy.advice import ACTIONS, what_next
    from pneumatic_unload.discrepancy.types import DiscrepancyResult

    base = _Fit((), 1e-8, 1e-11, 1000.0)
    r1 = _round(base, {"leak_downstream": _Fit(("leak_downstream",), 0.6e-8, 1e-11, 500.0),
                       "pipe_volume": _Fit(("pipe_volume",), 1e-8, 1e-11, 504.0)})
    assert (r1.winner, r1.ambiguous_with) == ("leak_downstream", ["pipe_volume"])
    b2 = r1.fits["leak_downstream"]
    r2 = _round(b2, {"sensor_lag": _Fit(("leak_downstream", "sensor_lag"), 0.6e-8, 1e-11,
                                        450.0)})
    res = SimpleNamespace(rounds=[r1], conductance_ambiguity=None, temperature_check=None,
                          after=_diag(True, 1.0), notes=[], effect=r1.winner,
                          before=_diag(False, 3.0), effects=[r1.winner], settings=None)
    res.named = DiscrepancyResult.named.fget(res)
    assert res.named == []
    advice = what_next(res)
    assert any(a.startswith("**Separate the candidates** (leak_downstream, pipe_volume")
               for a in advice), advice
    assert not any(ACTIONS["leak_downstream"] in a or ACTIONS["pipe_volume"] in a
                   for a in advice), advice
    res.rounds = [r1, r2]
    assert DiscrepancyResult.named.fget(res) == ["sensor_lag"]


# ------------------------------------- words, not numbers, for what cannot be known (issue)
def _fit_result(jac, *, fun=None, log=True):
    """A FitResult of a log parameter C and a linear one t_wall with the Jacobian given."""
    from pneumatic_unload.fit.lsq import FitResult
    from pneumatic_unload.fit.params import Parameter, Parameters

    params = Parameters([
        Parameter("C", 8.3e-9, 1e-13, 1e-5, "m^3/(s Pa)", log=log, scale=0.1,
                  doc="sonic conductance"),
        Parameter("t_wall", 315.0, 150.0, 600.0, "K", scale=5.0, doc="wall temperature")])
    jac = np.asarray(jac, dtype=float)
    fun = np.full(jac.shape[0], 0.5) if fun is None else np.asarray(fun, dtype=float)
    return FitResult(params=params, values=params.values(), x=params.to_x(), fun=fun, jac=jac,
                     chi2=float(fun @ fun), success=True, nfev=1, n_data=fun.size)


def _no_number_for_the_unknown(iv):
    """The interval's text, JSON and report row carry no open or overflowed end."""
    from pneumatic_unload.discrepancy.types import interval_dict

    d = interval_dict(iv)
    assert d["identifiable"] is False and d["ci_low"] is None and d["ci_high"] is None
    assert d["reason"] == iv.reason and iv.reason
    text = iv.describe()
    assert "e+30" not in text and "inf" not in text.replace("information", "")
    assert "[" not in text and "nan" not in text
    json.dumps(d, allow_nan=False)
    return text


def test_a_flat_direction_is_named_in_words_with_what_would_identify_it():
    # the trace changes with C exactly as with t_wall: the covariance is singular, the
    # linear interval of the log parameter C was [0, 1.014e+304] and said 'NOT identifiable'
    from pneumatic_unload.fit.profile import interval

    col = np.linspace(1.0, 2.0, 20)
    fit = _fit_result(np.column_stack([col, -2.0 * col]))
    iv = interval(None, None, fit, "C", math.inf, check=False)
    assert not iv.identifiable and iv.computed
    assert math.isnan(iv.low) and math.isnan(iv.high)
    text = _no_number_for_the_unknown(iv)
    assert text.startswith("not identifiable from this record: the trace changes with C "
                           "exactly as with a combination of t_wall"), text
    assert "what would identify it: C or t_wall fixed by a separate measurement" in text
    # a linear parameter with an infinite sigma was 'identifiable' with [-inf, inf]
    iv = interval(None, None, fit, "t_wall", math.inf, check=False)
    assert not iv.identifiable and "combination of C" in _no_number_for_the_unknown(iv)


def test_a_failed_evaluation_next_to_the_fit_is_not_called_a_property_of_the_record():
    # the AeroLab 0.094 in run: a step of C made the integration fail (BAD_RESIDUAL)
    from pneumatic_unload.fit.lsq import BAD_RESIDUAL, DIFF_STEP
    from pneumatic_unload.fit.profile import interval

    fun = np.full(20, 0.5)
    fit = _fit_result(np.column_stack([(BAD_RESIDUAL - fun) / DIFF_STEP,
                                       np.linspace(1.0, 2.0, 20)]), fun=fun)
    for name in ("C", "t_wall"):
        iv = interval(None, None, fit, name, math.inf, check=False)
        assert not iv.identifiable and not iv.computed
        text = _no_number_for_the_unknown(iv)
        assert text.startswith("uncertainty not known: the model could not be evaluated "
                               "next to the fit (a small step of C made the integration "
                               "fail)"), text
        assert "not a property of the record" in text


def test_a_too_wide_linear_interval_of_a_log_parameter_is_words_not_a_factor_of_1e304():
    from pneumatic_unload.fit.profile import interval

    fit = _fit_result(np.eye(20)[:, :2])
    iv = interval(None, None, fit, "C", 3.0e3, check=False)
    text = _no_number_for_the_unknown(iv)
    assert "the likelihood is nearly flat in C: its linear 95 % range spans more than a " \
           "factor of a million either side of the estimate" in text, text
    iv = interval(None, None, fit, "C", 25.0, check=False)  # e^(1.96 * 2.5) = 134
    assert "spans a factor of 134 either side" in _no_number_for_the_unknown(iv)
    ok = interval(None, None, fit, "C", 0.5, check=False)
    assert ok.identifiable and ok.reason == "" and ok.computed
    assert ok.describe() == f"95 % [{ok.low:.4g}, {ok.high:.4g}] (linear)"
    assert ok.low < 8.3e-9 < ok.high


def test_real_aerolab_unidentifiable_c_is_reported_in_words(tmp_path, capsys, monkeypatch):
    # issue: 'C = 8.3084e-09 m^3/(s Pa)  95 % [0, 1.014e+304] (linear, NOT identifiable)'
    import pneumatic_unload.discrepancy.report as report
    import pneumatic_unload.discrepancy.workflow as workflow

    path = REAL / "orifice_0.094in.csv"
    if not path.exists():
        pytest.skip(f"real data not present at {path}")
    results = []

    def keep(*args, **kwargs):
        results.append(find_discrepancy(*args, **kwargs))
        return results[-1]

    monkeypatch.setattr(workflow, "find_discrepancy", keep)
    monkeypatch.setattr(report, "write_plots",  # the text only: fast
                        lambda res, out: out.mkdir(parents=True, exist_ok=True) or {})
    rep = tmp_path / "rep"
    # read as analyze reads it (the run begins after its opening: its --start-time)
    code = main(["discrepancy", str(path), *aerolab_args(path.name), "--fit-wall-temperature",
                 "--no-profile", "--max-effects", "1", "--report", str(rep)])
    out = capsys.readouterr().out
    assert code == 0
    md = (rep / "report.md").read_text()
    doc = json.dumps(results[0].to_dict(), allow_nan=False)
    for text in (out, md, doc):
        assert "e+30" not in text and not re.search(r"\b-?inf\b", text), text
    for iv in results[0].to_dict()["parameters"].values():
        assert iv["identifiable"] or (iv["ci_low"] is None and iv["ci_high"] is None
                                      and iv["reason"]), iv
    (c_line,) = [x for x in out.splitlines() if x.startswith("  C = ")]
    assert re.fullmatch(r"  C = \S+ m\^3/\(s Pa\)  95 % \[\S+, \S+\] \(linear\)", c_line) or \
        "not identifiable from this record: " in c_line or \
        "uncertainty not known: " in c_line, c_line


def test_a_profile_open_at_one_end_keeps_the_closed_end_and_says_where_it_is_flat(
        monkeypatch):
    # an open profile end was 'inf' (text) or 'unbounded' (report): now the closed end is
    # kept and the flat stretch named, up to the end of the parameter's range
    import pneumatic_unload.fit.profile as profile
    from pneumatic_unload.discrepancy.types import interval_dict

    fit = _fit_result(np.eye(20)[:, :2])
    g0 = math.log(8.3e-9)

    def chi2(trace, model, fit_, name, value, **kw):  # flat above C = 8.3e-9, steep below
        g = math.log(value) - g0
        return fit_.chi2 + (100.0 * g * g if g < 0 else 0.0), None

    monkeypatch.setattr(profile, "profile_chi2", chi2)
    iv = profile.interval(None, None, fit, "C", 0.5)
    assert iv.method == "profile" and not iv.identifiable and iv.computed
    assert 0.8 * 8.3e-9 < iv.low < 8.3e-9 and math.isnan(iv.high)
    d = interval_dict(iv)
    assert d["ci_low"] == iv.low and d["ci_high"] is None
    text = iv.describe()
    assert text.startswith(f"not identifiable from this record: its 95 % lower end is "
                           f"{iv.low:.4g} m^3/(s Pa); the likelihood is flat in C (chi^2 "
                           "within 3.84 of its minimum) from the estimate 8.3e-09 m^3/(s Pa) "
                           "to the upper end of its range, 1e-05 m^3/(s Pa)"), text
    assert "what would identify it: " in text


def test_a_record_cut_after_its_opening_is_refused_in_words_and_read_from_its_start():
    """A discharge record that begins 0.5 s after its valve opening (no plateau, its fall
    under way at the first sample): the workflow passes on the estimator's refusal, which
    names the start time to give, not a bare 'no complete unload'; given the opening as
    ``start_time`` (and the atmosphere) the unload is located from there."""
    from pneumatic_unload.estimation.record_head import OPENING_HINT

    cfg = RigConfig(pre_time=1.0, duration=20.0, seed=5)
    sim = simulate(cfg)
    keep = sim.t >= 1.5
    t, y = sim.t[keep], sim.measured[keep]
    with pytest.raises(DiscrepancyError, match=OPENING_HINT):
        Problem(t, y, DiscrepancySettings(volume=cfg.volume, atmosphere=cfg.atmosphere))
    prob = Problem(t, y, DiscrepancySettings(volume=cfg.volume, atmosphere=cfg.atmosphere,
                                             start_time=float(t[0])))
    assert prob.start.t_open == pytest.approx(0.0, abs=1e-9)  # the shifted record's clock
    assert math.isfinite(prob.start.tau) and prob.start.tau > 0
