"""pneumatic_unload: sonic conductance of pneumatic components from a tank discharge.

The ROS-free core (``physics``, ``model``, ``detection``, ``estimation``, ``curvefit``,
``discrepancy``, ``io``) never imports rclpy; the ROS 2 nodes live in
``pneumatic_unload.nodes``. SI units everywhere: pressures in Pa absolute, temperatures in
K, volumes in m^3, times in s, sonic conductance C in m^3/(s Pa)
(1 dm^3/(s bar) = 1e-8 m^3/(s Pa)).
"""

__version__ = "0.1.0"
