# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The plateau before the valve opens as evidence of the gas's temperature (SI units): its
drift (a gas warmer or colder than the wall relaxing toward it, or a leak) and its bend
toward a level (a gas reaching the wall's temperature decays exponentially; a leak's decay
is straight over a plateau). Used by :mod:`pneumatic_unload.curvefit.law_family` to decide
where a hot start is fitted and claimed."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


#: A plateau drifts when its straight line's slope is at least this many of its
#: standard errors (the residuals' lag-1 correlation counted) [-]: the hot starts are then
#: fitted, and the criterion and the gap's gates decide (2, not 5: a 20 K warm gas on a
#: 1 s plateau at 100 Hz drifts by 2-3 of them and read at T10 = the room's gave C +5.7 %
#: at z 7.7, -1.1 % at z -0.5 with its hot start tried; a plateau of noise alone trips it
#: about 1 time in 15: its hot starts are screened by their first-order twin,
#: :meth:`Family._no_hot_start`, without which they widened C's heat-law line on 3 of 140
#: foreign-law records, sigma 0.04 % -> 0.4-1.7 %, C unchanged).
PLATEAU_DRIFT_Z = 2.0
#: Where T10 was not measured, a gas colder than the room (a tank vented, then shut) is read
#: only from a plateau that rises by this many of its standard errors [-]: a test line's
#: charge makes a warm gas, which is read from the record's shape; a cold one needs the
#: plateau's own evidence (a 2-sigma rise, 1 in 40 by chance, let a gauge's zero and a
#: subsonic index 0.3 be read as a gas 14 K cold, C +4.8 %).
COLD_DRIFT_Z = 5.0


def _plateau(t: FloatArray, p: FloatArray, t_open: float) -> tuple[FloatArray, FloatArray]:
    """The samples before the opening (two periods clear of it) [s], [Pa]."""
    pre = t < t_open - 2.0 * float(np.median(np.diff(t[:1001]))) if t.size > 2 else t < t_open
    return t[pre], p[pre]


def plateau_drift(t: FloatArray, p: FloatArray, t_open: float) -> float:
    """The slope of the samples before the opening (t [s] < t_open [s], p [Pa]; at least
    32) along a straight line, in its standard errors (the residuals' lag-1 correlation
    counted) [-]: negative where the plateau falls (a gas warmer than the wall cooling
    before the opening, or a leak), positive where it rises (a cold gas warming); 0 where
    the plateau is too short to tell."""
    tt, pp = _plateau(t, p, t_open)
    if tt.size < 32:
        return 0.0
    x = tt - tt.mean()
    sxx = float(x @ x)
    if sxx <= 0.0:
        return 0.0
    slope = float(x @ (pp - pp.mean())) / sxx
    r = pp - pp.mean() - slope * x
    s2 = float(r @ r) / (tt.size - 2)
    rho = float(r[1:] @ r[:-1]) / float(r @ r) if float(r @ r) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    se = math.sqrt(s2 / sxx * (1.0 + rho) / (1.0 - rho))
    return slope / se if se > 0.0 else 0.0


#: A plateau bending toward a level by this many of its standard errors is evidence of a
#: gas reaching the wall's temperature (not a leak) [-] (:func:`plateau_bend`; 2, as
#: :data:`PLATEAU_DRIFT_Z`: a 5 K warm gas, 3.3 K at the opening after a 2 s plateau at
#: 1 kHz, bends 2.3 of them: C +2.05 % -> +0.01 %; a laminar leak's plateau -1.1 to -1.3).
PLATEAU_BEND_Z = 2.0


def plateau_bend(t: FloatArray, p: FloatArray, t_open: float) -> float:
    """The bend of the samples before the opening (t [s] < t_open [s], p [Pa]; at least 64)
    toward a level, in its standard errors (the residuals' lag-1 correlation counted) [-]:
    the quadratic term of a parabola through them, positive where it opposes the slope (a
    gas cooling or warming toward the wall's temperature approaches it exponentially, its
    decay slowing), negative where the drift speeds up; 0 where the plateau is too short
    to tell or does not drift (a leak's decay, its time constant far longer than a
    plateau, is straight)."""
    tt, pp = _plateau(t, p, t_open)
    if tt.size < 64:
        return 0.0
    x = tt - tt.mean()
    a = np.column_stack([np.ones_like(x), x, x * x])
    coef, *_ = np.linalg.lstsq(a, pp, rcond=None)
    r = pp - a @ coef
    dof = tt.size - 3
    rr = float(r @ r)
    if rr <= 0.0 or coef[1] == 0.0:
        return 0.0
    rho = min(max(float(r[1:] @ r[:-1]) / rr, 0.0), 0.95)
    cov = np.linalg.inv(a.T @ a) * rr / dof * (1.0 + rho) / (1.0 - rho)
    se = math.sqrt(max(float(cov[2, 2]), 0.0))
    return -math.copysign(1.0, float(coef[1])) * float(coef[2]) / se if se > 0.0 else 0.0
