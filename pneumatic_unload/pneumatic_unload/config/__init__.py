# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Settings, declared once with units, ranges and meanings (SI units).

* :mod:`~pneumatic_unload.config.fields` - metadata-carrying fields and their validation;
* :mod:`~pneumatic_unload.config.tank` - :class:`TankSpec`, the tank and gas that every
  settings class embeds;
* :mod:`~pneumatic_unload.config.rig` - :class:`RigConfig`, the simulated rig;
* :mod:`~pneumatic_unload.config.adapters` - the only converters: command-line options, ROS
  parameters, JSON.
"""

from pneumatic_unload.config.fields import ConfigError
from pneumatic_unload.config.rig import EFFECTS, RigConfig, parse_effects
from pneumatic_unload.config.tank import TANK_FIELDS, TankSpec

__all__ = ["EFFECTS", "TANK_FIELDS", "ConfigError", "RigConfig", "TankSpec", "parse_effects"]
