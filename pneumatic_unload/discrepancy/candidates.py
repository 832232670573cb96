"""Parametrised discharge models: the baseline and the candidate effects it may miss.

The *baseline* is the paper's model: an adiabatic (isentropic) discharge of a tank through a
component obeying the ISO 6358 flow law, seen by an ideal sensor. Its free parameters are
C, b, the valve opening instant t_open and p10 (and p_atm when it is not known). The tank
volume V, T10 and the gas are given. The baseline is adiabatic on purpose: it is the model
whose bias the unloading-time method inherits, and wall heat transfer (always present on a
real rig) is then the first thing the workflow should find and quantify, as an effect with
a measured time constant rather than an assumed correlation.

Each candidate effect adds parameters with a physical meaning (SI units):

============== =========================== ===========================================
effect         parameter(s)                mapping onto :class:`RigConfig`
============== =========================== ===========================================
heat_transfer  tau_heat [s]                thermal time constant m0 c_v / (h A) of the
                                           gas-wall exchange, m0 = p10 V / (R T10):
                                           heat_transfer_mode 'fixed',
                                           h A = p10 V / ((gamma - 1) T10 tau_heat)
               (t_wall [K], optional)      wall temperature, when it is unknown
valve_opening  t_ramp [s]                  valve_opening_time (linear area ramp)
sensor_lag     tau_sensor [s]              sensor_lag (first-order time constant)
leak           leak_fraction [-]           leak flow at p10 over the choked flow at p10:
                                           K (p10 - p_atm) = f C rho_N p10 sqrt(T_N/T10)
pipe_volume    pipe_volume_ratio [-]       V2 / V (pipe_volume = ratio V)
               pipe_conductance_ratio [-]  C_pipe / C (pipe_conductance = ratio C)
sensor_offset  offset [Pa]                 sensor_offset
sensor_gain    gain [-]                    sensor_gain (relative)
============== =========================== ===========================================

Internally every parameter is fitted in a scaled coordinate x = (g(theta) - centre)/scale
with g = log for positive quantities, so that all coordinates are of order one.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import odeint

from pneumatic_unload.config import EFFECTS, RigConfig
from pneumatic_unload.model import _make_rhs, sensor_response
from pneumatic_unload.physics import RHO_N, T_N, Gas

FloatArray = NDArray[np.float64]

#: Extra pseudo-effect: a constant geometric factor on C (the paper's L/D effect).
GEOMETRY_FACTOR = "geometry_factor"


@dataclass(frozen=True)
class Param:
    """One fitted parameter.

    Attributes
    ----------
    name : str
        Key.
    unit : str
        SI unit.
    log : bool
        Fitted as log(value) (positive quantities).
    lo, hi : float
        Bounds of the value [unit].
    doc : str
        Meaning.
    """

    name: str
    unit: str
    log: bool
    lo: float
    hi: float
    doc: str


#: Parameters each effect adds (see the module docstring for the mapping).
EFFECT_PARAMS: dict[str, tuple[Param, ...]] = {
    "heat_transfer": (Param("tau_heat", "s", True, 1e-3, 1e5,
                            "thermal time constant m0 c_v/(h A) of the gas-wall exchange"),),
    "valve_opening": (Param("t_ramp", "s", True, 1e-5, 10.0,
                            "valve opening time (linear ramp of the effective area)"),),
    "sensor_lag": (Param("tau_sensor", "s", True, 1e-6, 10.0,
                         "first-order time constant of the pressure sensor"),),
    "leak": (Param("leak_fraction", "-", True, 1e-5, 10.0,
                   "leak flow at p10 relative to the choked flow at p10"),),
    "pipe_volume": (Param("pipe_volume_ratio", "-", True, 1e-4, 20.0,
                          "volume between tank and component, relative to V"),
                    Param("pipe_conductance_ratio", "-", True, 1e-2, 1e4,
                          "sonic conductance of the pipe relative to C")),
    "sensor_offset": (Param("offset", "Pa", False, -1e6, 1e6, "transducer zero offset"),),
    "sensor_gain": (Param("gain", "-", False, -0.5, 0.5, "transducer relative gain error"),),
}

WALL_TEMPERATURE = Param("t_wall", "K", False, 150.0, 600.0, "wall temperature")

#: Which extra measurement separates two confusable effects.
SEPARATING_DATA: dict[frozenset[str], str] = {
    frozenset({"valve_opening", "sensor_lag"}):
        "a valve position signal (or a faster discharge: a bigger component or a smaller "
        "tank makes the valve ramp and the sensor lag distort different parts of the curve)",
    frozenset({"sensor_offset", "sensor_gain"}):
        "a zero reading at atmosphere and a reference reading at a known pressure (a "
        "calibrated manometer at p10)",
    frozenset({"heat_transfer", "pipe_volume"}):
        "a gas temperature measurement, or a run with the pipe shortened",
    frozenset({"heat_transfer", "leak"}):
        "a leak test: hold the charged tank closed and watch the pressure",
    frozenset({"leak", "pipe_volume"}):
        "a leak test (closed tank held at p10) or a run with the pipe shortened",
    frozenset({"sensor_offset", "leak"}):
        "a zero reading at atmosphere, or a leak test (closed tank held at p10)",
    frozenset({"sensor_gain", "leak"}):
        "a leak test (closed tank held at p10) and a calibration of the transducer",
}


def separating_data(names: list[str]) -> list[str]:
    """Advice: which extra data would separate each pair of confusable effects."""
    out: list[str] = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            hint = SEPARATING_DATA.get(frozenset({a, b}))
            out.append(f"{a} vs {b}: " + (hint or "a second run with a different tank "
                                           "volume or initial pressure"))
    return out


@dataclass(frozen=True)
class RigInfo:
    """What is known about the rig (not fitted).

    Attributes
    ----------
    volume : float
        Tank volume V [m^3].
    initial_temperature : float
        T10 [K].
    wall_temperature : float
        Wall temperature [K] (starting value when it is fitted).
    length_diameter_ratio : float
        Tank L/D [-].
    atmosphere : float or None
        p_atm [Pa absolute]; None: fitted.
    gas : Gas
        Gas properties.
    fit_wall_temperature : bool
        Fit the wall temperature with the heat-transfer effect.
    """

    volume: float
    initial_temperature: float
    wall_temperature: float
    length_diameter_ratio: float
    atmosphere: float | None
    gas: Gas
    fit_wall_temperature: bool = False


@dataclass(frozen=True)
class Start:
    """Neutral values of the baseline parameters (from the unloading-time estimate).

    Attributes
    ----------
    conductance : float
        C [m^3/(s Pa)].
    critical_ratio : float
        b [-].
    t_open : float
        Valve opening instant [s] (relative to the first sample).
    p10 : float
        Initial pressure [Pa absolute].
    p_atm : float
        Atmospheric pressure [Pa absolute].
    tau : float
        Unloading time tau_exp [s].
    dt : float
        Sample period [s].
    """

    conductance: float
    critical_ratio: float
    t_open: float
    p10: float
    p_atm: float
    tau: float
    dt: float


class ModelSpec:
    """The baseline plus a set of effects, with its parameter vector and coordinates.

    Parameters
    ----------
    effects : tuple of str
        Effects switched on (names from :data:`pneumatic_unload.config.EFFECTS`).
    rig : RigInfo
        Known rig data.
    start : Start
        Neutral values (centres of the scaled coordinates).
    """

    def __init__(self, effects: tuple[str, ...], rig: RigInfo, start: Start) -> None:
        bad = [e for e in effects if e not in EFFECTS]
        if bad:
            raise ValueError(f"unknown effect(s) {bad}")
        self.effects = tuple(effects)
        self.rig = rig
        self.start = start
        p = start.p10
        params = [
            Param("C", "m^3/(s Pa)", True, 1e-13, 1e-5, "sonic conductance"),
            Param("b", "-", False, 0.01, 0.95, "critical pressure ratio"),
            Param("t_open", "s", False, -1e9, 1e9, "valve opening instant"),
            Param("p10", "Pa", False, 0.3 * p, 3.0 * p, "initial pressure (absolute)"),
        ]
        if rig.atmosphere is None:
            params.append(Param("p_atm", "Pa", False, 0.3 * start.p_atm, 3.0 * start.p_atm,
                                "atmospheric pressure (absolute)"))
        for e in self.effects:
            params.extend(EFFECT_PARAMS[e])
            if e == "heat_transfer" and rig.fit_wall_temperature:
                params.append(WALL_TEMPERATURE)
        self.params = tuple(params)
        self.names = tuple(q.name for q in params)
        centre, scale = [], []
        for q in params:
            c, s = self._centre_scale(q)
            centre.append(c)
            scale.append(s)
        self.centre = np.array(centre)
        self.scale = np.array(scale)

    def _centre_scale(self, q: Param) -> tuple[float, float]:
        s = self.start
        table = {
            "C": (math.log(s.conductance), 0.1),
            "b": (s.critical_ratio, 0.1),
            "t_open": (s.t_open, max(10.0 * s.dt, 1e-3 * s.tau)),
            "p10": (s.p10, 1e-3 * s.p10),
            "p_atm": (s.p_atm, 1e-3 * s.p_atm),
            "tau_heat": (math.log(s.tau), 1.0),
            "t_wall": (self.rig.wall_temperature, 5.0),
            "t_ramp": (math.log(max(s.tau * 0.01, 3 * s.dt)), 1.0),
            "tau_sensor": (math.log(max(s.tau * 0.01, 3 * s.dt)), 1.0),
            "leak_fraction": (math.log(0.05), 1.0),
            "pipe_volume_ratio": (math.log(0.1), 1.0),
            "pipe_conductance_ratio": (math.log(5.0), 1.0),
            "offset": (0.0, 1000.0),
            "gain": (0.0, 0.01),
        }
        return table[q.name]

    @property
    def k(self) -> int:
        """Number of free parameters [-]."""
        return len(self.params)

    # coordinates ----------------------------------------------------------------------
    def to_x(self, theta: dict[str, float]) -> FloatArray:
        """Scaled coordinates of a parameter dict (values in SI units)."""
        g = np.array([math.log(theta[q.name]) if q.log else theta[q.name] for q in self.params])
        return (g - self.centre) / self.scale

    def to_theta(self, x: FloatArray) -> dict[str, float]:
        """Parameter dict (SI units) of scaled coordinates."""
        g = self.centre + self.scale * np.asarray(x, dtype=float)
        return {q.name: float(math.exp(v) if q.log else v)
                for q, v in zip(self.params, g, strict=True)}

    def bounds(self, t_first: float, t_last: float) -> tuple[FloatArray, FloatArray]:
        """Bounds of the scaled coordinates (t_open within the record)."""
        lo, hi = [], []
        for q in self.params:
            a, b = q.lo, q.hi
            if q.name == "t_open":
                a, b = t_first, min(t_last, self.start.t_open + 0.5 * self.start.tau)
            if q.log:
                a, b = math.log(a), math.log(b)
            lo.append(a)
            hi.append(b)
        return ((np.array(lo) - self.centre) / self.scale,
                (np.array(hi) - self.centre) / self.scale)

    def clip_x(self, x: FloatArray, t_first: float, t_last: float) -> FloatArray:
        """x moved strictly inside the bounds."""
        lo, hi = self.bounds(t_first, t_last)
        eps = 1e-9 * (hi - lo)
        return np.clip(np.asarray(x, dtype=float), lo + eps, hi - eps)

    # the model ------------------------------------------------------------------------
    def config(self, theta: dict[str, float]) -> RigConfig:
        """The :class:`RigConfig` of a parameter dict (valve opens at ``theta['t_open']``)."""
        rig = self.rig
        gas = rig.gas
        c = float(np.clip(theta["C"], 1e-13, 1e-5))
        p10 = theta["p10"]
        p_atm = theta.get("p_atm", rig.atmosphere if rig.atmosphere is not None else 101325.0)
        t10 = rig.initial_temperature
        kw: dict[str, object] = {}
        if "tau_heat" in theta:
            h_a = p10 * rig.volume / ((gas.gamma - 1.0) * t10 * theta["tau_heat"])
            kw.update(heat_transfer_mode="fixed",
                      heat_transfer_coefficient=float(np.clip(h_a, 0.0, 1e4)))
        if "t_ramp" in theta:
            kw["valve_opening_time"] = float(min(theta["t_ramp"], 10.0))
        if "tau_sensor" in theta:
            kw["sensor_lag"] = float(min(theta["tau_sensor"], 10.0))
        if "leak_fraction" in theta:
            g0 = c * RHO_N * p10 * math.sqrt(T_N / t10)
            k_leak = theta["leak_fraction"] * g0 / max(p10 - p_atm, 1.0)
            kw["leak_coefficient"] = float(np.clip(k_leak, 0.0, 1e-5))
        if "pipe_volume_ratio" in theta:
            kw["pipe_volume"] = float(min(theta["pipe_volume_ratio"] * rig.volume, 10.0))
            kw["pipe_conductance"] = float(np.clip(theta["pipe_conductance_ratio"] * c,
                                                   1e-13, 1e-5))
        if "offset" in theta:
            kw["sensor_offset"] = theta["offset"]
        if "gain" in theta:
            kw["sensor_gain"] = float(np.clip(theta["gain"], -0.5, 0.5))
        return RigConfig(
            volume=rig.volume, length_diameter_ratio=rig.length_diameter_ratio,
            conductance=c, critical_ratio=float(np.clip(theta["b"], 0.0, 0.99)),
            initial_pressure=float(np.clip(p10, 1e4, 5e7)), initial_temperature=t10,
            atmosphere=float(np.clip(p_atm, 1e3, 2e5)),
            wall_temperature=theta.get("t_wall", rig.wall_temperature),
            gas_constant=gas.gas_constant, gamma=gas.gamma, effects=self.effects,
            pre_time=0.0, noise_std=0.0, **kw)  # type: ignore[arg-type]

    def signal(self, theta: dict[str, float], t: FloatArray) -> FloatArray:
        """Noise-free sensor output of the model at instants t [Pa]."""
        cfg = self.config(theta)
        p, _ = fast_discharge(cfg, t, theta["t_open"])
        return sensor_response(t, p, cfg)

    def temperature(self, theta: dict[str, float], t: FloatArray) -> FloatArray:
        """Mean gas temperature of the model at instants t [K]."""
        cfg = self.config(theta)
        return fast_discharge(cfg, t, theta["t_open"])[1]


def fast_discharge(cfg: RigConfig, t: FloatArray, t_open: float, *, rtol: float = 1e-8
                   ) -> tuple[FloatArray, FloatArray]:
    """Same as :func:`pneumatic_unload.model.discharge`, integrated in segments.

    :func:`~pneumatic_unload.model.discharge` limits the integrator step to a quarter of
    the valve ramp over the *whole* record, which makes long records with a short ramp
    slow; here only the ramp segment is limited. Same right-hand side, same tolerances;
    the tests check that both agree.

    Parameters
    ----------
    cfg : RigConfig
        Rig, component and effects.
    t : ndarray
        Increasing output instants [s]; the state at t[0] is (p10, T10).
    t_open : float
        Valve opening instant [s].
    rtol : float
        Relative tolerance [-].

    Returns
    -------
    tuple of ndarray
        (tank pressure [Pa absolute], gas temperature [K]).
    """
    with warnings.catch_warnings():
        # fits explore extreme parameters where LSODA complains; the likelihood rejects
        # non-finite or absurd outputs itself
        warnings.simplefilter("ignore")
        return _segmented(cfg, np.asarray(t, dtype=float), t_open, rtol)


def _segmented(cfg: RigConfig, t: FloatArray, t_open: float, rtol: float
               ) -> tuple[FloatArray, FloatArray]:
    """Body of :func:`fast_discharge` (same arguments and units)."""
    ramp = cfg.valve_opening_time if cfg.has("valve_opening") else 0.0
    rhs, _ = _make_rhs(cfg, t_open)
    y0 = [cfg.initial_pressure, cfg.initial_temperature]
    atol = [cfg.initial_pressure * rtol * 1e-2, cfg.initial_temperature * rtol * 1e-2]
    if cfg.has("pipe_volume"):
        y0.append(cfg.initial_pressure)
        atol.append(atol[0])
    t_end_ramp = t_open + ramp
    if ramp <= 0 or not t[0] < t_end_ramp < t[-1]:
        crit = np.unique([c for c in (t_open, t_end_ramp) if t[0] <= c <= t[-1]])
        y = odeint(rhs, y0, t, tfirst=True, rtol=rtol, atol=atol, mxstep=200_000,
                   tcrit=crit if crit.size else None, hmax=ramp / 4.0 if ramp > 0 else 0.0)
        return y[:, 0].copy(), y[:, 1].copy()
    k = int(np.searchsorted(t, t_end_ramp, side="right"))
    ta = np.concatenate((t[:k], [t_end_ramp]))
    crit = np.array([c for c in (t_open, t_end_ramp) if t[0] <= c])
    ya = odeint(rhs, y0, ta, tfirst=True, rtol=rtol, atol=atol, mxstep=200_000,
                tcrit=crit, hmax=ramp / 4.0)
    tb = np.concatenate(([t_end_ramp], t[k:]))
    yb = odeint(rhs, ya[-1], tb, tfirst=True, rtol=rtol, atol=atol, mxstep=200_000)
    y = np.concatenate((ya[:-1], yb[1:]))
    return y[:, 0].copy(), y[:, 1].copy()
