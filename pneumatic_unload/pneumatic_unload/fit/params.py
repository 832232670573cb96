# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Named, bounded fit parameters (the lmfit ``Parameters`` shape).

A :class:`Parameter` carries its value, bounds, unit and whether it varies. The engine fits
every free parameter in a scaled coordinate x = (g(value) - centre)/scale, with g = log for
positive quantities (``log=True``) and the identity otherwise, so that every coordinate is of
order one and finite differences and trust regions treat them alike. SI units for values.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class ParameterError(ValueError):
    """A parameter definition or value is invalid (unknown name, bounds, non-finite)."""


@dataclass(frozen=True)
class Parameter:
    """One fit parameter.

    Attributes
    ----------
    name : str
        Key.
    value : float
        Value [unit]: the start of a fit, or the fixed value when ``vary`` is False.
    lo, hi : float
        Bounds [unit] (log parameters need lo > 0).
    unit : str
        SI unit.
    log : bool
        Fitted as log(value).
    scale : float
        Typical change of g(value) [unit, or log units]: one unit of the scaled coordinate.
    centre : float or None
        g(value) at x = 0 [unit or log units]; None: g of ``value``.
    vary : bool
        Free (True) or held at ``value``.
    doc : str
        Physical meaning.
    fade : float
        For a log parameter whose effect is about linear in value^p near the end where it
        fades (p = 1: a multiplier going to 0; p = -1: a time constant going to infinity),
        p [-]: a step towards that end is taken along value^p (see
        :meth:`Parameters.step`); 0 (default): along the log.
    """

    name: str
    value: float
    lo: float = -math.inf
    hi: float = math.inf
    unit: str = ""
    log: bool = False
    scale: float = 1.0
    centre: float | None = None
    vary: bool = True
    doc: str = ""
    fade: float = 0.0

    def __post_init__(self) -> None:
        """Validate bounds and scale (raises :class:`ParameterError`)."""
        if not self.lo < self.hi:
            raise ParameterError(f"{self.name}: lower bound {self.lo} is not below {self.hi}")
        if self.log and not self.lo > 0:
            raise ParameterError(f"{self.name}: a log parameter needs a positive lower bound")
        if not (self.scale > 0 and math.isfinite(self.scale)):
            raise ParameterError(f"{self.name}: scale must be a positive number")
        if not math.isfinite(self.value):
            raise ParameterError(f"{self.name}: value {self.value!r} is not finite")
        if self.fade != 0.0 and not self.log:
            raise ParameterError(f"{self.name}: fade needs a log parameter")

    def g(self, value: float) -> float:
        """Fitted coordinate before scaling: log(value) or value."""
        return math.log(value) if self.log else float(value)

    def g_inv(self, g: float) -> float:
        """Value [unit] of an unscaled coordinate."""
        return math.exp(g) if self.log else float(g)

    @property
    def g_centre(self) -> float:
        """Centre of the scaled coordinate, in g units."""
        return self.g(self.value) if self.centre is None else self.centre


class Parameters:
    """An ordered set of :class:`Parameter` (the free ones are fitted).

    Parameters
    ----------
    params : iterable of Parameter
        Parameters in order; names must be unique.
    """

    def __init__(self, params: Iterable[Parameter]) -> None:
        params = list(params)
        self._p = {p.name: p for p in params}
        if len(params) != len(self._p):
            raise ParameterError(f"duplicate parameter names in {[p.name for p in params]}")
        # freeze the centres at construction so that later value changes keep x stable
        self._p = {k: dataclasses.replace(p, centre=p.g_centre) for k, p in self._p.items()}

    def __iter__(self) -> Iterator[Parameter]:
        return iter(self._p.values())

    def __getitem__(self, name: str) -> Parameter:
        try:
            return self._p[name]
        except KeyError:
            raise ParameterError(f"no parameter {name!r}; have {list(self._p)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._p

    def __len__(self) -> int:
        return len(self._p)

    @property
    def names(self) -> tuple[str, ...]:
        """All names, in order."""
        return tuple(self._p)

    @property
    def free(self) -> tuple[str, ...]:
        """Names of the varying parameters, in order."""
        return tuple(k for k, p in self._p.items() if p.vary)

    def values(self) -> dict[str, float]:
        """Current values [units]."""
        return {k: p.value for k, p in self._p.items()}

    def replace(self, *, fixed: dict[str, float] | None = None, **values: float
                ) -> Parameters:
        """A copy with new values; names in ``fixed`` are held at the value given."""
        fixed = fixed or {}
        out = []
        for k, p in self._p.items():
            if k in fixed:
                out.append(dataclasses.replace(p, value=float(fixed[k]), vary=False))
            elif k in values:
                out.append(dataclasses.replace(p, value=float(values[k])))
            else:
                out.append(p)
        unknown = set(values) | set(fixed)
        unknown -= set(self._p)
        if unknown:
            raise ParameterError(f"unknown parameter(s) {sorted(unknown)}")
        return Parameters(out)

    # scaled coordinates of the free parameters ------------------------------------------
    def to_x(self, values: dict[str, float] | None = None) -> FloatArray:
        """Scaled coordinates of the free parameters (values default to the current)."""
        v = self.values() if values is None else {**self.values(), **values}
        return np.array([(p.g(v[p.name]) - p.g_centre) / p.scale
                         for p in self._p.values() if p.vary])

    def to_values(self, x: FloatArray) -> dict[str, float]:
        """All values [units] for scaled coordinates x of the free parameters."""
        out = {}
        it = iter(np.asarray(x, dtype=float))
        for k, p in self._p.items():
            out[k] = p.g_inv(p.g_centre + p.scale * float(next(it))) if p.vary else p.value
        return out

    def step(self, x: FloatArray, dx: FloatArray) -> FloatArray:
        """Scaled coordinates after a step dx from x: x + dx, except for the parameters
        with a ``fade`` power p moving towards the end where their effect fades (p dg < 0,
        dg = scale dx their log's change): they move as value^p does under the same
        first-order change, to value^p (1 + p dg). Gauss-Newton along the log moves such a
        value by at most a factor e per step (its effect is about linear in value^p there:
        the step predicts value^p -> 0 at most); along value^p it reaches the optimum in
        one. A step that would take value^p past 0 is cut where it reaches 0 (every
        coordinate's move scaled alike): that parameter lands on its bound. Not clipped
        to the bounds."""
        x = np.asarray(x, dtype=float)
        dx = np.asarray(dx, dtype=float)
        free = [p for p in self._p.values() if p.vary]
        dg = np.array([p.scale * float(d) for p, d in zip(free, dx, strict=True)])
        fading = [k for k, p in enumerate(free) if p.fade * dg[k] < 0.0
                  and abs(p.g_centre + p.scale * float(x[k]) - p.g(_fade_end(p))) > 1e-9]
        if not fading:  # (one already on its bound stays there: the caller clips)
            return x + dx
        cut = min(1.0, *(-1.0 / (free[k].fade * dg[k]) for k in fading))
        out = x + cut * dx
        for k in fading:
            p = free[k]
            z = 1.0 + p.fade * cut * dg[k]
            g = p.g(_fade_end(p)) if z <= 1e-12 else \
                p.g_centre + p.scale * float(x[k]) + math.log(z) / p.fade
            out[k] = (g - p.g_centre) / p.scale
        return out

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Bounds of the scaled coordinates of the free parameters."""
        lo, hi = [], []
        for p in self._p.values():
            if p.vary:
                lo.append((p.g(p.lo) - p.g_centre) / p.scale)
                hi.append((p.g(p.hi) - p.g_centre) / p.scale)
        return np.array(lo), np.array(hi)

    def value_std(self, name: str, value: float, x_std: float) -> float:
        """Standard deviation [unit] of a value from that of its scaled coordinate."""
        p = self[name]
        return (value if p.log else 1.0) * p.scale * x_std


def _fade_end(p: Parameter) -> float:
    """The bound [unit] at the end where a fading parameter's effect fades."""
    return p.lo if p.fade > 0 else p.hi
