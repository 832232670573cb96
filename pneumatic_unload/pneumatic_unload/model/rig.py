# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""An endless, stateful sample stream of a simulated rig: what the simulator node publishes.

:class:`RigStream` holds the tank charged at p10, unloads when told (:meth:`RigStream.open_valve`),
vents to atmosphere and, when told (:meth:`RigStream.charge`), recharges to p10. Samples come
out in blocks at the configured rate, through the same sensor chain as
:func:`pneumatic_unload.model.simulate` (first-order lag, gain, offset, white and AR(1)
noise, quantisation, saturation), but with every filter carrying its state across blocks
and phases, so that a live stream never jumps. The discharge itself is
:func:`pneumatic_unload.model.discharge` with the rig's effects: the node and the offline
``pneumatic-unload simulate`` run the same model.

Times are relative to the stream's start [s]; pressures [Pa absolute]; temperatures [K].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import ConfigError, RigConfig
from pneumatic_unload.model import SensorChain, default_duration, discharge

FloatArray = NDArray[np.float64]

#: Phases of a :class:`RigStream`.
PHASES = ("charged", "unloading", "vented", "charging")


@dataclass
class Block:
    """A block of consecutive samples of a :class:`RigStream`.

    Attributes
    ----------
    index : ndarray of int
        Sample numbers k (t = k / rate) [-].
    t : ndarray
        Sample instants relative to the stream's start [s].
    measured : ndarray
        Sensor output [Pa as indicated].
    pressure : ndarray
        True tank pressure [Pa absolute].
    temperature : ndarray
        Gas temperature [K].
    opening : ndarray
        Valve effective-area fraction [0, 1].
    """

    index: NDArray[np.int64]
    t: FloatArray
    measured: FloatArray
    pressure: FloatArray
    temperature: FloatArray
    opening: FloatArray


class RigStream:
    """Stateful sample generator of a tank-discharge rig.

    Parameters
    ----------
    cfg : RigConfig
        Rig, effects and sensor; ``cfg.seed`` seeds the noise; ``cfg.duration`` (0: 6 tau)
        is how long the unload is integrated before the tank is held at its last state.
    charge_time : float
        Duration of a recharge from the vented state to p10 [s].
    """

    def __init__(self, cfg: RigConfig, *, charge_time: float = 1.0) -> None:
        if not charge_time > 0:
            raise ValueError(f"charge_time must be > 0 s, got {charge_time!r}")
        self.cfg = cfg
        self.charge_time = float(charge_time)
        self._chain = SensorChain(cfg.seed)
        self._k = 0  # next sample number
        self._phase = "charged"
        self._phase_k0 = 0
        self._p_hold = cfg.initial_pressure
        self._temp_hold = cfg.initial_temperature
        self._p_charge0 = cfg.initial_pressure
        self._unload_p: FloatArray = np.empty(0)
        self._unload_temp: FloatArray = np.empty(0)
        self._close_after = math.inf
        self.unloads = 0

    # ------------------------------------------------------------------ state
    @property
    def phase(self) -> str:
        """'charged', 'unloading', 'vented' or 'charging'."""
        return self._phase

    @property
    def next_index(self) -> int:
        """Number k of the next sample (its instant is k / rate) [-]."""
        return self._k

    @property
    def period(self) -> float:
        """Sample period [s]."""
        return 1.0 / self.cfg.rate

    def reconfigure(self, cfg: RigConfig) -> None:
        """Use ``cfg`` from the next unload or charge on (the current phase is unchanged).

        The rate cannot change while streaming (sample numbers would lose their meaning).
        """
        if cfg.rate != self.cfg.rate:
            raise ValueError("the sample rate cannot change while the rig is streaming")
        self.cfg = cfg
        if self._phase == "charged":
            self._p_hold = cfg.initial_pressure
            self._temp_hold = cfg.initial_temperature

    def open_valve(self) -> str:
        """Start an unload at the next sample.

        Returns
        -------
        str
            '' when the unload started, else why not (the tank is not charged).
        """
        if self._phase != "charged":
            return f"the tank is not charged (phase {self._phase}); charge it first"
        cfg = self.cfg
        dur = cfg.duration if cfg.duration > 0 else default_duration(cfg)
        n = max(2, math.floor(dur * cfg.rate) + 1)
        t = np.arange(n, dtype=float) / cfg.rate
        p, temp = discharge(cfg.replace(pre_time=0.0), t, 0.0)
        self._unload_p, self._unload_temp = p, temp
        self._close_after = cfg.valve_close_time if cfg.valve_close_time > 0 else math.inf
        self._phase, self._phase_k0 = "unloading", self._k
        self.unloads += 1
        return ""

    def charge(self) -> str:
        """Recharge to p10 from the next sample (a smooth ramp over ``charge_time``).

        Returns
        -------
        str
            '' when charging started, else why not.
        """
        if self._phase in ("charging", "charged"):
            return f"the tank is already {self._phase}"
        self._phase, self._phase_k0 = "charging", self._k
        self._p_charge0 = self._p_hold
        return ""

    def reverse(self) -> str:
        """Turn the flow for the next step: the tank, held where the last step left it
        (pressure and gas temperature), is its initial state; after a charge, a discharge
        from there to the atmosphere, after a discharge a charge from there toward
        ``supply_pressure`` (ISO 6358-2's two tests of one component in turn; the wall
        stays at its temperature).

        Returns
        -------
        str
            '' when the tank is ready for the reversed step (opened by :meth:`open_valve`),
            else why not (only after a step, from the vented state).
        """
        if self._phase != "vented":
            return f"the flow turns after a step (phase {self._phase})"
        cfg = self.cfg
        try:
            self.cfg = cfg.replace(
                direction="discharge" if cfg.direction == "charge" else "charge",
                initial_pressure=self._p_hold, initial_temperature=self._temp_hold,
                wall_temperature=cfg.wall)
        except ConfigError as exc:
            return f"the flow cannot turn: {exc}"
        self._phase, self._phase_k0 = "charged", self._k
        return ""

    # ------------------------------------------------------------------ samples
    def next_block(self, n: int) -> Block:
        """The next ``n`` samples (true state and sensor output).

        Parameters
        ----------
        n : int
            Number of samples [-] (>= 1).
        """
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        cfg = self.cfg
        k = np.arange(self._k, self._k + n, dtype=np.int64)
        t = k / cfg.rate
        p = np.empty(n)
        temp = np.empty(n)
        opening = np.zeros(n)
        j = 0
        while j < n:  # phases may change inside the block
            j = self._fill(k, p, temp, opening, j)
        self._k += n
        y = self._sensor(t, p)
        return Block(index=k, t=t, measured=y, pressure=p, temperature=temp, opening=opening)

    def _fill(self, k: NDArray[np.int64], p: FloatArray, temp: FloatArray,
              opening: FloatArray, j: int) -> int:
        """Fill samples j.. of the current phase; return the first index not filled."""
        n = k.size
        cfg = self.cfg
        if self._phase in ("charged", "vented"):
            p[j:] = self._p_hold
            temp[j:] = self._temp_hold
            return n
        rel = k[j:] - self._phase_k0
        if self._phase == "unloading":
            m = self._unload_p.size
            stop = int(np.searchsorted(rel, m))
            p[j:j + stop] = self._unload_p[rel[:stop]]
            temp[j:j + stop] = self._unload_temp[rel[:stop]]
            tr = rel[:stop] / cfg.rate
            opening[j:j + stop] = np.where(tr < self._close_after, 1.0, 0.0)
            if cfg.has("valve_opening") and cfg.valve_opening_time > 0:
                opening[j:j + stop] *= np.clip(tr / cfg.valve_opening_time, 0.0, 1.0)
            if stop < rel.size:
                self._p_hold = float(self._unload_p[-1])
                self._temp_hold = float(self._unload_temp[-1])
                self._phase, self._phase_k0 = "vented", int(k[j + stop])
            return j + stop
        # charging: p goes from the vented level to p10 along a raised cosine
        m = max(1, round(self.charge_time * cfg.rate))
        stop = int(np.searchsorted(rel, m))
        x = rel[:stop] / m
        p0, p1 = self._p_charge0, cfg.initial_pressure
        p[j:j + stop] = p0 + (p1 - p0) * 0.5 * (1.0 - np.cos(np.pi * x))
        temp[j:j + stop] = cfg.initial_temperature
        if stop < rel.size:
            self._p_hold, self._temp_hold = p1, cfg.initial_temperature
            self._phase, self._phase_k0 = "charged", int(k[j + stop])
        return j + stop

    def _sensor(self, t: FloatArray, p: FloatArray) -> FloatArray:
        """Sensor chain with its state carried across blocks [Pa as indicated]."""
        return self._chain.apply(t, p, self.cfg)


def run_cycles(cfg: RigConfig, unloads: int, *, settle_time: float = 2.0,
               vent_time: float = 1.0, charge_time: float = 1.0,
               alternate: bool = False) -> Block:
    """A recorded run of several unloads, as the simulator node's cycle mode produces it.

    ``cfg.pre_time`` of charged plateau, then per unload: the unload (``cfg.duration``, or
    6 tau when 0), ``vent_time`` vented, and (except after the last one) a recharge of
    ``charge_time`` and ``settle_time`` of plateau before the next unload.

    Parameters
    ----------
    cfg : RigConfig
        Rig, effects and sensor.
    unloads : int
        Number of unloads [-] (>= 1).
    settle_time, vent_time, charge_time : float
        Phase durations [s].
    alternate : bool
        Each step in turn the other way (:meth:`RigStream.reverse`: a charge then a
        discharge of the same component, no recharge between them), starting with
        ``cfg.direction``.

    Returns
    -------
    Block
        All samples of the run (t from 0 [s]).
    """
    if unloads < 1:
        raise ValueError(f"unloads must be >= 1, got {unloads}")
    rs = RigStream(cfg, charge_time=charge_time)
    rate = cfg.rate
    blocks: list[Block] = []

    def take(seconds: float) -> None:
        n = round(seconds * rate)
        if n > 0:
            blocks.append(rs.next_block(n))

    take(cfg.pre_time)
    for k in range(unloads):
        rs.open_valve()
        take(cfg.duration if cfg.duration > 0 else default_duration(cfg))
        while rs.phase == "unloading":
            take(0.1)
        take(vent_time)
        if k + 1 < unloads and alternate:
            why = rs.reverse()
            if why:
                raise ValueError(why)
            take(settle_time)
        elif k + 1 < unloads:
            rs.charge()
            take(charge_time)
            take(settle_time)
    return Block(*(np.concatenate([getattr(b, f) for b in blocks])
                   for f in ("index", "t", "measured", "pressure", "temperature", "opening")))
