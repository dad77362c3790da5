"""simreal: physics-based augmented reality.

The package has a ROS-free numerical core (``physics``, ``rom``, ``vision``, ``assimilation``,
``collision``, ``render``, ``synth``, ``scene``, ``io``: numpy in, numpy out) and thin rclpy
adapters in ``simreal_nodes.ros``. Nothing outside ``simreal_nodes.ros`` imports rclpy. ``studies`` holds
reproductions of the thesis' studies (chapter 3) that the running system does not use.
"""

__version__ = "0.1.0"
