"""pneumatic_unload: sonic conductance of pneumatic components from a tank discharge or
charge.

The ROS-free core never imports rclpy. Its parts, lowest first (``test/test_layout.py``'s
``LAYERS`` enforces the order): ``physics`` and ``charge`` (closed forms), ``config``,
``io`` and ``fit`` (the fitting engine), ``model``, ``uncertainty`` (the budgets),
``curvefit`` (the model-based C, b, m), ``estimation`` (streaming and batch),
``discrepancy``, ``analysis`` and ``testline``, then ``app`` (CLI, demo, launcher) and
``plc`` (OPC UA). The ROS 2 nodes live in ``pneumatic_unload.nodes``. SI units
everywhere: pressures in Pa absolute, temperatures in K, volumes in m^3, times in s, sonic
conductance C in m^3/(s Pa) (1 dm^3/(s bar) = 1e-8 m^3/(s Pa)).
"""

__version__ = "0.1.0"
