# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The discharge model: one ODE with one integrator, one heat law, one sensor chain.

Modules, each of one role (SI units throughout):

* :mod:`~pneumatic_unload.model.kernel` - the compiled core (``kernel.c``): flow law, heat
  laws, right-hand side, integrator;
* :mod:`~pneumatic_unload.model.heat` - the wall heat-transfer laws' parameters;
* :mod:`~pneumatic_unload.model.ode` - the configuration packed for the kernel, the
  segmented integration;
* :mod:`~pneumatic_unload.model.sensor` - the sensor chain, batch and stateful;
* :mod:`~pneumatic_unload.model.effects` - the registry of real-rig effects;
* :mod:`~pneumatic_unload.model.simulate` - a simulated record on the sample grid;
* :mod:`~pneumatic_unload.model.rig` - the simulator's endless, stateful sample stream (what
  the simulator node publishes);
* :mod:`~pneumatic_unload.model.inversion` - the model inverted at the p* crossing: the C
  that reaches p* at the measured tau_exp (directly, or from a table), and the estimator's
  model built from its settings.

The model's bin means for the likelihood are computed by :mod:`pneumatic_unload.fit.likelihood`
from the model evaluated at its quadrature nodes.
"""

from pneumatic_unload.model.heat import HEAT_LAWS, heat_flow_function, thermal_time_constant
from pneumatic_unload.model.ode import (
    discharge,
    integrate,
    opening_fraction,
    opening_ramp,
    right_hand_side,
    state_size,
    valve_events,
)
from pneumatic_unload.model.sensor import (
    SensorChain,
    digitise,
    first_order_lag,
    sensor_response,
)
from pneumatic_unload.model.simulate import (
    Simulation,
    default_duration,
    model_signal,
    simulate,
    time_grid,
    valve_opening,
)

__all__ = [
    "HEAT_LAWS",
    "SensorChain",
    "Simulation",
    "default_duration",
    "digitise",
    "discharge",
    "first_order_lag",
    "heat_flow_function",
    "integrate",
    "model_signal",
    "opening_fraction",
    "opening_ramp",
    "right_hand_side",
    "sensor_response",
    "simulate",
    "state_size",
    "thermal_time_constant",
    "time_grid",
    "valve_events",
    "valve_opening",
]
