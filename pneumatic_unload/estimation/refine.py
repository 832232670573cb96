"""Refinement: model inversion at the crossing, final curve fit, SSE recovery fit.

The only module of the package that calls :mod:`pneumatic_unload.fitting` (imported lazily:
it pulls in scipy), so those calls can be re-pointed in one place. SI units: s, Pa
absolute, m^3/(s Pa); the recovery fit works in the input's signal units.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pneumatic_unload.estimation.types import EstimatorSettings, FloatArray, UnloadResult


def model_inversion(settings: EstimatorSettings, tau: float, tau_std: float, p10: float,
                    p_atm: float, p_star: float, c_isen: float) -> tuple[float, float, str]:
    """Model-based C: exact inversion of the discharge model at the crossing.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and heat-model settings.
    tau, tau_std : float
        Time from the start to the crossing of ``p_star`` and its 1-sigma [s].
    p10, p_atm, p_star : float
        Initial, atmospheric and crossing pressures [Pa absolute].
    c_isen : float
        Isentropic-inversion C, the start value [m^3/(s Pa)].

    Returns
    -------
    tuple
        (C [m^3/(s Pa)], its 1-sigma [m^3/(s Pa)], method name).
    """
    from pneumatic_unload.fitting import invert_crossing, may_turn_subsonic  # local: light

    if settings.heat_model == "adiabatic" and not may_turn_subsonic(settings, p_atm, p_star):
        # choked up to p*: the isentropic closed form is the adiabatic model's exact inverse
        c = c_isen
        std = c * tau_std / tau
        return c, std, "eq39+isentropic-inversion"
    c, std = invert_crossing(
        tau, tau_std, p10=p10, p_atm=p_atm, p_star=p_star, settings=settings, c_start=c_isen)
    law = "natural-convection" if settings.heat_model == "natural" else "adiabatic"
    return c, std, f"eq39+model-inversion({law})"


def final_curve_fit(res: UnloadResult, t: FloatArray, p: FloatArray,
                    settings: EstimatorSettings, *, noise_std: float) -> UnloadResult | None:
    """Final result of an unload from the full-curve fit (None when it fails).

    Parameters
    ----------
    res : UnloadResult
        The unload's crossing result.
    t, p : ndarray
        Samples of the unload and its tail [s], [Pa absolute].
    settings : EstimatorSettings
        Tank, gas and heat-model settings.
    noise_std : float
        Noise standard deviation [Pa].
    """
    from pneumatic_unload.fitting import refine_with_curve_fit

    return refine_with_curve_fit(res, t, p, settings, noise_std=noise_std)


def recovery_fit(t: FloatArray, p: FloatArray, t_close: float) -> Any:
    """Fit of the isochoric re-heating after the closing instant t_close [s] (samples t [s],
    p [signal units]); None when the fit fails."""
    from pneumatic_unload.recovery import fit_recovery

    try:
        return fit_recovery(t, p, t_close)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return None
