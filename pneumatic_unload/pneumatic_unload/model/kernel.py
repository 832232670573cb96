# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The compiled core of the discharge model: flow law, heat laws, right-hand side, integrator.

The formulae live once, in C (``kernel.c`` beside this file): the ISO 6358 flow function,
the wall heat laws, the tank's mass and energy balance and the integrator: Dormand-Prince
5(4) with its continuous extension, switching for the rest of a segment to the Rosenbrock
2(3) W-method of Shampine & Reichelt (MATLAB's ode23s; finite-difference Jacobian) when
Hairer's stiffness test fires (a pipe volume far smaller than the tank, a very fast heat
exchange). The package's build (setup.py: a setuptools extension, so
``colcon build`` and ``pip install`` do it) compiles that file into a shared library beside
it (``_kernel.so.0``, with the hash of the source compiled in: :func:`prebuilt`); the
installed package needs no compiler at run time. Where that library is missing or was
built from another text (a source tree without a build, an edited ``kernel.c``), this
module builds it with the system's C compiler the first time it is needed (``cc -O2``,
about 0.3 s) under a name that holds the hash of the source and the flags (an edited
``kernel.c`` is never run stale), written beside the source when that folder is writable,
else in ``$XDG_CACHE_HOME/pneumatic_unload``; ``PNEUMATIC_UNLOAD_KERNEL_DIR`` overrides
both. It calls the library through :mod:`ctypes`.

Why compiled: a curve fit evaluates the model 30-60 times; the right-hand side as Python
floats cost 2-4 ms per evaluation (the live final fit missed its 50 ms budget by 4x); this
integrator takes about 0.1 ms for the same discharge and imports in milliseconds.

Functions (SI units: Pa absolute, K, m^3, s, kg/s, W):

* :func:`flow_phi` - phi(r) (the scalar twin of :func:`pneumatic_unload.physics.flow_function`;
  a test holds them equal);
* :func:`heat_flow` - the wall heat laws of :mod:`pneumatic_unload.model.heat`;
* :func:`opening` - the valve's opening fraction;
* :func:`rhs` - dy/dt of the discharge for a parameter vector
  (:func:`pneumatic_unload.model.ode.kernel_parameters` packs it);
* :func:`dopri5` - the integrator over one smooth segment (stiff-switching), output on any
  grid;
* :func:`integrate` - :func:`dopri5` over the smooth segments between the valve events, in
  one call (a fit's model evaluation: no Python per segment);
* :func:`lag` - the sensor's exact first-order lag on an uneven grid (the quadrature
  nodes of a fit), :func:`pneumatic_unload.model.sensor.first_order_lag`'s loop.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

# Slots of the parameter vector of :func:`rhs` (the enum of kernel.c, checked at load).
GAMMA, R_GAS, CP, VOLUME, P_ATM, T_WALL = 0, 1, 2, 3, 4, 5
B_RATIO, M_INDEX, C_RHO, LEAK = 6, 7, 8, 9
HEAT_MODE, HEAT_A, HEAT_RA = 10, 11, 12
PIPE, PIPE_VOLUME, PIPE_C_RHO = 13, 14, 15
T_OPEN, RAMP, T_CLOSE, R_LIN, SQRT_TN = 16, 17, 18, 19, 20
# leaks: downstream laminar k [kg/(s Pa)]; orifice-law leaks C rho_n [kg/(s Pa)] and b [-],
# upstream (always open) and downstream (opens with the valve, parallel to the component)
LEAK_DOWN, OLEAK_C_RHO, OLEAK_B, OLEAK_DOWN_C_RHO, OLEAK_DOWN_B = 21, 22, 23, 24, 25
# multiplier on the turbulent branch of the natural-convection correlation [-]
HEAT_TURB = 26
# a charge (1.0; 0.0: a discharge) from a supply at P_SUPPLY [Pa abs], T_SUPPLY [K]; the
# coefficient of its jet-driven convection, hA = HEAT_JET |G_in|^JET_EXPONENT [W/K]
CHARGE, P_SUPPLY, T_SUPPLY, HEAT_JET = 27, 28, 29, 30
# the exponent q of the component's subsonic ellipse, phi = (1 - x^q)^m [-] (2: ISO 6358-1)
Q_EXPONENT = 31
# a second ISO element in series downstream of the component (ISO 6358-3): its
# conductance over the component's upstream element's, kappa = C2/C1 [-] (0: none), its
# b and m [-]; C_RHO is then the pair's and B_RATIO, M_INDEX the upstream element's
# (and the choked pair's intermediate ratio, :func:`series_choked`, packed with them)
SERIES_KAPPA, SERIES_B, SERIES_M, SERIES_X0 = 32, 33, 34, 35
# the time law's hA = HEAT_A exp(g1 u + g2 u^2), u = ln(1 + s / HEAT_TREF), s the time since
# the opening: g1, g2 [-] and the time scale [s]
HEAT_G1, HEAT_G2, HEAT_TREF = 36, 37, 38
N_PARAMETERS = 39
#: Exponent of the inflow's Reynolds number in a charge's jet-driven convection
#: (JET_EXPONENT of kernel.c) [-].
JET_EXPONENT = 0.67

#: Subsonic index m of the orifice-law leaks [-] (LEAK_M_INDEX of kernel.c).
LEAK_M_INDEX = 0.5

#: Heat-law codes of the HEAT_MODE slot.
HEAT_NONE, HEAT_NATURAL, HEAT_FIXED, HEAT_DENSITY, HEAT_TIME = 0.0, 1.0, 2.0, 3.0, 4.0

#: Return codes of :func:`dopri5`.
OK, TOO_MANY_STEPS, STEP_TOO_SMALL, NOT_FINITE = 0, 1, 2, 3

#: The most states the integrator takes (MAX_STATES of kernel.c).
MAX_STATES = 8

SOURCE = Path(__file__).with_name("kernel.c")
CFLAGS = ("-O2", "-fPIC", "-shared", "-std=c99")


class KernelBuildError(RuntimeError):
    """The C kernel could not be compiled or loaded (no C compiler, no writable folder)."""


def library_name(source: Path | None = None) -> str:
    """File name of the library built from ``source`` (default: ``kernel.c``): its stem and
    the hash of the source, the flags and the machine."""
    source = SOURCE if source is None else source
    h = hashlib.sha256(source.read_bytes())
    h.update(" ".join(CFLAGS).encode())
    h.update(platform.machine().encode())
    return f"pneumatic_unload_{source.stem}-{h.hexdigest()[:16]}.so"


def library_dirs(source: Path | None = None) -> list[Path]:
    """Folders searched (and written, first writable one) for the library built from
    ``source`` (default: ``kernel.c``)."""
    env = os.environ.get("PNEUMATIC_UNLOAD_KERNEL_DIR")
    if env:
        return [Path(env)]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return [(SOURCE if source is None else source).parent / "__pycache__",
            cache / "pneumatic_unload"]


def source_sha(source: Path | None = None) -> str:
    """The hash of ``source`` (default: ``kernel.c``) that setup.py compiles into the
    library it builds (``PU_SOURCE_SHA``): 16 hex digits of its SHA-256."""
    return hashlib.sha256((SOURCE if source is None else source).read_bytes()).hexdigest()[:16]


def prebuilt(source: Path | None = None) -> Path | None:
    """The library the package's build compiled from ``source`` (default: ``kernel.c``;
    setup.py's ``_<stem>.so.0`` beside it), if it was built from this very text
    (its ``pu_source_sha``); None otherwise (a source tree without a build, an edited
    source)."""
    source = SOURCE if source is None else source
    for path in [source.with_name(f"_{source.stem}.so.0")]:
        if not path.is_file():
            continue
        try:
            lib = ctypes.CDLL(str(path))
            fn = lib.pu_source_sha
        except (OSError, AttributeError):
            continue
        fn.restype = ctypes.c_char_p
        if fn().decode() == source_sha(source):
            return path
    return None


def build(folder: Path | None = None, source: Path | None = None) -> Path:
    """Compile ``source`` (default: ``kernel.c``; the package's other C source is the
    estimator's crossing fit, ``estimation/regression.c``) into ``folder`` (default: the
    first writable of :func:`library_dirs`) and return the library's path; nothing to do
    when it exists.

    Raises
    ------
    KernelBuildError
        No C compiler (``$CC``, ``cc`` or ``gcc``), or the compiler failed, or no folder is
        writable.
    """
    source = SOURCE if source is None else source
    if folder is None:
        pre = prebuilt(source)
        if pre is not None:  # compiled when the package was built or installed
            return pre
    name = library_name(source)
    dirs = [folder] if folder is not None else library_dirs(source)
    for d in dirs:
        if (d / name).exists():
            return d / name
    cc = shutil.which(os.environ.get("CC") or "cc") or shutil.which("gcc")
    if not cc:
        raise KernelBuildError(
            f"the discharge model and the estimator's crossing fit are compiled C ({source})"
            f" and no C compiler was found ({os.environ.get('CC') or 'cc'}, gcc): install "
            "gcc (Debian: apt install gcc) or set CC")
    errors = []
    for d in dirs:
        try:
            d.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".kernel-", suffix=".so", dir=d)
            os.close(fd)
        except OSError as exc:
            errors.append(f"{d}: {exc}")
            continue
        try:
            # in a session of its own: a Ctrl-C to the terminal's process group (a node
            # stopped while it builds) does not kill the compiler under the node's handler
            proc = subprocess.run([cc, *CFLAGS, "-o", tmp, str(source), "-lm"],
                                  capture_output=True, text=True, check=False,
                                  start_new_session=True)
            if proc.returncode != 0:
                raise KernelBuildError(f"compiling {source} with {cc} failed:\n"
                                       f"{proc.stderr.strip()}")
            os.replace(tmp, d / name)  # atomic: concurrent builders never see half a file
            return d / name
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    raise KernelBuildError("no writable folder for the compiled kernel: "
                           + "; ".join(errors) + " (set PNEUMATIC_UNLOAD_KERNEL_DIR)")


def _load() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(build()))
    dbl, i32, i64 = ctypes.c_double, ctypes.c_int, ctypes.c_long
    arr = ctypes.c_void_p  # float64 C-contiguous data, passed as ndarray.ctypes.data
    lib.pu_n_parameters.restype = i32
    if lib.pu_n_parameters() != N_PARAMETERS:
        raise KernelBuildError("kernel.c and kernel.py disagree on the parameter slots")
    lib.pu_flow_phi.restype = dbl
    lib.pu_flow_phi.argtypes = [dbl] * 5
    lib.pu_series_phi.restype = dbl
    lib.pu_series_phi.argtypes = [dbl] * 7
    lib.pu_series_choked.restype = dbl
    lib.pu_series_choked.argtypes = [dbl] * 4
    lib.pu_component_phi_array.restype = None
    lib.pu_component_phi_array.argtypes = [i32, arr] + [dbl] * 7 + [arr]
    lib.pu_heat_flow.restype = dbl
    lib.pu_heat_flow.argtypes = [dbl] * 7
    lib.pu_opening.restype = dbl
    lib.pu_opening.argtypes = [dbl] * 4
    lib.pu_rhs.restype = None
    lib.pu_rhs.argtypes = [dbl, arr, arr, arr]
    lib.pu_dopri5.restype = i32
    lib.pu_dopri5.argtypes = [i32, arr, dbl, dbl, i32, arr, arr, dbl, arr, dbl, i64, arr,
                              ctypes.POINTER(i32)]
    lib.pu_integrate.restype = i32
    lib.pu_integrate.argtypes = [i32, arr, i32, arr, i32, arr, arr, dbl, arr, dbl, dbl, i64,
                                 arr, ctypes.POINTER(i32), ctypes.POINTER(i32), arr]
    lib.pu_lag.restype = None
    lib.pu_lag.argtypes = [i32, arr, arr, dbl, dbl, dbl, dbl, i32, arr]
    return lib


_LIB = _load()


def flow_phi(r: float, b: float, m: float, r_linear: float, q: float = 2.0) -> float:
    """ISO 6358 flow function phi(r) of the pressure ratio r = p2/p1 [-].

    1 for r <= b (choked); [1 - ((r - b)/(1 - b))^q]^m up to r_linear; linear in (1 - r)
    above, 0 at r = 1 and negative beyond (reverse flow). b: critical pressure ratio [-];
    m: subsonic index [-]; r_linear [-]; q: the ellipse's exponent [-] (2 in ISO
    6358-1:2013; another q: a flow curve that is not ISO-shaped).
    """
    return float(_LIB.pu_flow_phi(r, b, m, q, r_linear))


def series_phi(r: float, b1: float, m1: float, b2: float, m2: float, kappa: float,
               r_linear: float) -> float:
    """Flow function phi(r) [-] of two ISO 6358-1 elements in series (ISO 6358-3: one mass
    flow, one stagnation temperature, no volume between), normalised by the pair's choked
    flow: the upstream element (b1, m1), the downstream one (b2, m2) of conductance kappa
    times the upstream one's [-]; linear in (1 - r) above r_linear [-] as the ISO law."""
    return float(_LIB.pu_series_phi(r, b1, m1, b2, m2, kappa, r_linear))


def series_choked(b1: float, m1: float, kappa: float, r_linear: float) -> float:
    """The intermediate ratio p_i/p1 [-] of :func:`series_phi`'s pair when it is choked
    (the SERIES_X0 slot)."""
    return float(_LIB.pu_series_choked(b1, m1, kappa, r_linear))


def component_phi(r: FloatArray, b: float, m: float, r_linear: float, *, q: float = 2.0,
                  series: tuple[float, float, float] | None = None) -> FloatArray:
    """The component's flow function at the ratios r [-]: the ISO law (b, m, q) of
    :func:`flow_phi`, or with ``series`` = (b2, m2, kappa) the pair of :func:`series_phi`
    whose upstream element is (b, m)."""
    r = np.ascontiguousarray(r, dtype=float)
    out = np.empty_like(r)
    b2, m2, kappa = series if series is not None else (0.5, 0.5, 0.0)
    _LIB.pu_component_phi_array(r.size, r.ctypes.data, b, m, q, b2, m2, kappa, r_linear,
                                out.ctypes.data)
    return out


def heat_flow(mode: float, coeff: float, ra_const: float, t_wall: float, p: float,
              t_gas: float, turb: float = 1.0) -> float:
    """Wall heat flow into the gas Q [W] at pressure p [Pa] and gas temperature t_gas [K].

    mode :data:`HEAT_NATURAL`: Q = coeff Nu(Ra) (T_w - T), Nu = 0.59 Ra^0.25 (laminar) or
    turb 0.10 Ra^(1/3) (Ra >= 1e9; turb [-] scales the turbulent branch alone), Nu >= 1,
    Ra = ra_const |T_w - T|/T (p/T)^2, coeff = A_w k/L times the heat-transfer scale [W/K];
    mode :data:`HEAT_FIXED`: Q = coeff (T_w - T), coeff = hA [W/K]; mode
    :data:`HEAT_DENSITY`: Q = coeff (p/T)^n (T_w - T), n = ra_const [-],
    coeff = hA_0 (T_0/p_0)^n (hA_0 [W/K] at the gas density of p_0 [Pa], T_0 [K]);
    mode :data:`HEAT_TIME`: Q = coeff (T_w - T) at the opening (the right-hand side
    multiplies coeff by exp(g1 u + g2 u^2) as time passes); :data:`HEAT_NONE`: 0. t_wall:
    wall temperature [K].
    """
    return float(_LIB.pu_heat_flow(mode, coeff, ra_const, t_wall, p, t_gas, turb))


def opening(t: float, t_open: float, ramp: float, t_close: float) -> float:
    """Valve effective-area fraction a(t) [-]: 0 before t_open [s] and from t_close [s],
    a linear ramp of ``ramp`` [s] (0: a step), then 1."""
    return float(_LIB.pu_opening(t, t_open, ramp, t_close))


def rhs(t: float, y: FloatArray, prm: FloatArray, dy: FloatArray) -> None:
    """dy/dt of the discharge written into ``dy``: y = (p [Pa], T [K][, p_pipe [Pa]]) at
    t [s] for the parameter vector ``prm`` -> (Pa/s, K/s[, Pa/s])."""
    y = np.ascontiguousarray(y, dtype=float)
    if prm.dtype != np.float64 or dy.dtype != np.float64 or not dy.flags.c_contiguous \
            or dy.size < y.size or prm.size != N_PARAMETERS:
        raise ValueError("rhs: dy and prm must be float64 arrays of the right sizes")
    _LIB.pu_rhs(t, y.ctypes.data, prm.ctypes.data, dy.ctypes.data)


def _checked(name: str, y0: FloatArray, t_out: FloatArray, atol: FloatArray,
             prm: FloatArray, out: FloatArray
             ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The integrators' arrays as C-contiguous float64, their sizes checked (ValueError)."""
    y0 = np.ascontiguousarray(y0, dtype=float)
    t_out = np.ascontiguousarray(t_out, dtype=float)
    atol = np.ascontiguousarray(atol, dtype=float)
    prm = np.ascontiguousarray(prm, dtype=float)
    if prm.size != N_PARAMETERS or not 1 <= y0.size <= MAX_STATES or atol.size != y0.size \
            or out.shape != (t_out.size, y0.size) or not out.flags.c_contiguous \
            or out.dtype != np.float64:
        raise ValueError(f"{name}: inconsistent array sizes or types")
    return y0, t_out, atol, prm


def dopri5(y0: FloatArray, t0: float, t1: float, t_out: FloatArray, prm: FloatArray,
           rtol: float, atol: FloatArray, hmax: float, max_steps: int,
           out: FloatArray) -> tuple[int, int]:
    """Integrate dy/dt = :func:`rhs` from (t0, y0) to t1 and write y at the instants t_out.

    Dormand-Prince 5(4) (local extrapolation, FSAL) with its 4th-order continuous extension
    for the output, so the steps follow the dynamics, not the grid; step control on the RMS
    norm of the error scaled by atol + rtol |y|. After 15 accepted steps at the stability
    limit (h |lambda| > 3.25) the rest of the segment is integrated by the Rosenbrock 2(3)
    W-method (L-stable, its own interpolant), so stiff configurations cost thousands of
    steps, not hundreds of thousands.

    Parameters
    ----------
    y0 : ndarray
        State at t0 (units of :func:`rhs`), at most :data:`MAX_STATES` entries.
    t0, t1 : float
        Segment [s], t1 > t0; the right-hand side must be smooth inside it.
    t_out : ndarray
        Increasing output instants in [t0, t1] [s].
    prm : ndarray
        Parameter vector of :func:`rhs` (:data:`N_PARAMETERS` entries).
    rtol : float
        Relative tolerance [-].
    atol : ndarray
        Absolute tolerance per state (units of y).
    hmax : float
        Largest step [s] (0: no limit).
    max_steps : int
        Step budget [-].
    out : ndarray
        C-contiguous (len(t_out), len(y0)) array receiving the states.

    Returns
    -------
    tuple of int
        (status: :data:`OK`, :data:`TOO_MANY_STEPS`, :data:`STEP_TOO_SMALL` or
        :data:`NOT_FINITE`; number of rows of ``out`` written).
    """
    y0, t_out, atol, prm = _checked("dopri5", y0, t_out, atol, prm, out)
    done = ctypes.c_int(0)
    status = _LIB.pu_dopri5(y0.size, y0.ctypes.data, float(t0), float(t1), t_out.size,
                            t_out.ctypes.data, prm.ctypes.data, float(rtol), atol.ctypes.data,
                            float(hmax), int(max_steps), out.ctypes.data, ctypes.byref(done))
    return int(status), int(done.value)



def integrate(y0: FloatArray, bounds: FloatArray, t_out: FloatArray, prm: FloatArray,
              rtol: float, atol: FloatArray, t_open: float, ramp: float, max_steps: int,
              out: FloatArray) -> tuple[int, int, int, FloatArray]:
    """:func:`dopri5` over the smooth segments between ``bounds``, the state carried across.

    In a segment that ends before the valve opens, the state stays where it is when the
    gas is at rest (dy/dt = 0 at its start); inside the opening ramp the step is at most a
    quarter of it.

    Parameters
    ----------
    y0 : ndarray
        State at t_out[0] (units of :func:`rhs`).
    bounds : ndarray
        Segment ends [s]: t_out[0], the valve events inside, t_out[-1].
    t_out : ndarray
        Increasing output instants [s] (at least one).
    prm : ndarray
        Parameter vector of :func:`rhs`.
    rtol, atol : float, ndarray
        Relative and absolute (per state) tolerances.
    t_open, ramp : float
        Valve opening instant and ramp duration [s].
    max_steps : int
        Step budget of each segment [-].
    out : ndarray
        C-contiguous (len(t_out), len(y0)) float64 array receiving the states.

    Returns
    -------
    tuple
        (status as :func:`dopri5`; rows of ``out`` written; the failing segment's index,
        -1 when none; the state at that segment's start).
    """
    y0, t_out, atol, prm = _checked("integrate", y0, t_out, atol, prm, out)
    bounds = np.ascontiguousarray(bounds, dtype=float)
    if bounds.size < 2 or t_out.size < 1:
        raise ValueError("integrate: inconsistent array sizes or types")
    done, seg = ctypes.c_int(0), ctypes.c_int(-1)
    y_fail = np.zeros(y0.size)
    status = _LIB.pu_integrate(y0.size, y0.ctypes.data, bounds.size, bounds.ctypes.data,
                               t_out.size, t_out.ctypes.data, prm.ctypes.data, float(rtol),
                               atol.ctypes.data, float(t_open), float(ramp), int(max_steps),
                               out.ctypes.data, ctypes.byref(done), ctypes.byref(seg),
                               y_fail.ctypes.data)
    return int(status), int(done.value), int(seg.value), y_fail
def lag(t: FloatArray, u: FloatArray, tau: float, state: tuple[float, float, float],
        steady: bool) -> FloatArray:
    """Exact first-order lag y' = (u - y)/tau of the piecewise-linear interpolant of u.

    Parameters
    ----------
    t : ndarray
        Increasing instants [s] (any spacing).
    u : ndarray
        Input at t [any unit].
    tau : float
        Time constant [s] (> 0).
    state : tuple
        (t, u, y) of the previous sample [s, unit, unit].
    steady : bool
        Start in steady state at the first sample (y = u there).

    Returns
    -------
    ndarray
        The lagged samples [unit of u].
    """
    t = np.ascontiguousarray(t, dtype=float)
    u = np.ascontiguousarray(u, dtype=float)
    if t.shape != u.shape or t.ndim != 1:
        raise ValueError("lag: t and u must be 1-D arrays of equal length")
    y = np.empty_like(u)
    _LIB.pu_lag(u.size, t.ctypes.data, u.ctypes.data, float(tau), float(state[0]),
                float(state[1]), float(state[2]), int(bool(steady)), y.ctypes.data)
    return y
