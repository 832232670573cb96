# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A recorded trace prepared for fitting a parametric model with the binned likelihood.

:class:`Trace` holds relative times, the noise model and the
:class:`~pneumatic_unload.fit.likelihood.BinnedLikelihood`; :meth:`Trace.fit` fits any
model that has ``parameters`` (:class:`~pneumatic_unload.fit.params.Parameters`),
``signal(values, t)`` and ``events(values)`` through :func:`~pneumatic_unload.fit.lsq.minimize`,
evaluating the model only at the likelihood's quadrature nodes. SI units: s, Pa.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.fit.likelihood import BinnedLikelihood, BinStats, make_bins
from pneumatic_unload.fit.lsq import FitResult, minimize
from pneumatic_unload.fit.noise import NoiseModel
from pneumatic_unload.fit.params import Parameters

FloatArray = NDArray[np.float64]
Values = dict[str, float]


class FitTimeout(RuntimeError):
    """The trace's deadline (:attr:`Trace.deadline`) passed during a fit."""


class FittableModel(Protocol):
    """What :class:`Trace` needs of a model (units of the trace)."""

    parameters: Parameters

    def signal(self, v: Values, t: FloatArray) -> FloatArray:
        """Noise-free signal at instants t [Pa]."""
        ...

    def events(self, v: Values) -> list[float]:
        """Instants where the signal is not smooth [s]."""
        ...


@dataclass(frozen=True)
class TemperatureChannel:
    """A logged gas temperature fitted beside the pressure (a model with
    ``thermometer_grid``, ``signal_and_temperature`` and ``seen``, see
    :class:`pneumatic_unload.model.parametric.ParametricModel`).

    Attributes
    ----------
    t : ndarray
        The thermometer's sample instants [s, the trace's relative times], increasing, at
        least three; its first reading is the lag's initial state, not a residual.
    temp : ndarray
        Its readings [K].
    weight : float
        Pa per K of a temperature residual: the pressure residual's standard deviation over
        the temperature's [Pa/K], so that both channels' residuals have one variance.
    lag : float or None
        The thermometer's time constant held [s] (given, or one the readings' spacing
        cannot resolve); None: fitted.
    offset : bool
        The thermometer's offset [K] is fitted (its readings are the lagged gas
        temperature plus it); False: held at 0.
    """

    t: FloatArray
    temp: FloatArray
    weight: float
    lag: float | None = None
    offset: bool = False

    @property
    def n(self) -> int:
        """Residuals the channel adds [-]."""
        return int(self.temp.size) - 1

    def residual(self, seen: FloatArray) -> FloatArray:
        """Weighted readings minus the model's readings ``seen`` [K] (at :attr:`t`)
        [Pa-equivalent]."""
        return self.weight * (self.temp[1:] - seen[1:])


class Trace:
    """A trace ready for fitting.

    Parameters
    ----------
    t, y : ndarray
        Sample instants [s] (relative to any origin, increasing) and signal [Pa].
    noise : NoiseModel
        AR(1) noise model (sigma 1: unnormalised residuals, variance estimated after).
    t_open : float
        Expected valve opening [s] (where the bins are finest).
    resolution : float
        Relative bin width [-].
    edges : ndarray, optional
        Bin edges to use instead of :func:`make_bins`.
    """

    def __init__(self, t: FloatArray, y: FloatArray, noise: NoiseModel, t_open: float, *,
                 resolution: float = 0.03, edges: NDArray[np.int64] | None = None) -> None:
        self.t = np.asarray(t, dtype=float)
        self.y = np.asarray(y, dtype=float)
        self.noise = noise
        if edges is None:
            edges = make_bins(self.t, t_open, resolution=resolution)
        self.lik = BinnedLikelihood(self.t, self.y, noise, edges)
        #: :func:`time.monotonic` instant [s] after which an evaluation raises
        #: :class:`FitTimeout` (None: no deadline); one evaluation is the granularity.
        self.deadline: float | None = None
        #: A logged gas temperature fitted beside (None: the pressure alone).
        self.channel: TemperatureChannel | None = None

    def with_channel(self, channel: TemperatureChannel | None) -> Trace:
        """This trace with ``channel`` fitted beside the pressure (the likelihood shared)."""
        out = copy.copy(self)
        out.channel = channel
        return out

    @classmethod
    def from_stats(cls, stats: BinStats, noise: NoiseModel) -> Trace:
        """A trace given by its bins (:class:`~pneumatic_unload.fit.likelihood.BinStats`,
        times relative to any origin [s]) instead of its samples (``t`` and ``y`` None)."""
        self = cls.__new__(cls)
        self.t = self.y = None
        self.noise = noise
        self.lik = BinnedLikelihood.from_stats(stats, noise)
        self.deadline = None
        self.channel = None
        return self

    @property
    def n(self) -> int:
        """Samples [-]."""
        return self.lik.n

    def residual(self, model: FittableModel) -> Callable[[Values], FloatArray]:
        """The normalised binned residual of ``model`` as a function of its values [-],
        the temperature channel's weighted residuals after it when there is one.

        Raises :class:`FitTimeout` once :attr:`deadline` has passed.
        """
        lik, ch = self.lik, self.channel

        def fun(v: Values) -> FloatArray:
            if self.deadline is not None and time.monotonic() > self.deadline:
                raise FitTimeout("the time limit passed during a fit")
            if ch is None:
                return lik.residuals_at(lambda tt: model.signal(v, tt), model.events(v))
            # one integration gives the pressure at the likelihood's nodes and the gas
            # temperature the thermometer follows
            m: Any = model
            grid = m.thermometer_grid(v, ch.t)
            gas: list[FloatArray] = []

            def at(tt: FloatArray) -> FloatArray:
                p, g = m.signal_and_temperature(v, tt, grid)
                gas.append(g)
                return p

            r = lik.residuals_at(at, model.events(v))
            seen = m.seen(v, grid, gas[-1], ch.t, float(ch.temp[0]))
            return np.concatenate((r, ch.residual(seen)))

        return fun

    def fit(self, model: FittableModel, *, starts: list[Values] | None = None,
            fixed: Values | None = None, start: Values | None = None,
            screen_nfev: int = 12, max_nfev: int = 200, fade: bool = False) -> FitResult:
        """Fit ``model`` to the trace.

        Parameters
        ----------
        model : FittableModel
            Model with its parameters (starting values and bounds).
        starts : list of dict, optional
            Further starting values, screened (see :func:`minimize`) [units].
        fixed : dict, optional
            Parameters held at the values given [units].
        start : dict, optional
            Replaces the parameters' starting values [units].
        screen_nfev, max_nfev : int
            Evaluation budgets [-].
        fade : bool
            Step fading effects' parameters along their power (see :func:`minimize`).
        """
        names = set(model.parameters.names)
        params = model.parameters.replace(fixed=fixed or {},
                                          **{k: v for k, v in (start or {}).items()
                                             if k in names and k not in (fixed or {})})
        starts = [{k: v for k, v in s.items() if k in names} for s in (starts or [])]
        return minimize(self.residual(model), params, starts=starts,
                        screen_nfev=screen_nfev, max_nfev=max_nfev, n_data=self.n,
                        fade=fade)
