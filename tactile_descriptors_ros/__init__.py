"""tactile_descriptors_ros: robust tactile descriptors and online material recognition for ROS 2.

Subpackages: ``core`` (pure numpy: descriptors, windowing, learning),
``codecs`` (wire formats), ``transports`` (SPI, serial, CAN, simulated),
``sim`` (scene simulator), ``nodes`` (rclpy nodes), ``tools`` (the
``tactile`` command).  Importing this package imports none of them.
"""

__all__ = ["__version__"]
__version__ = "0.1.0"
