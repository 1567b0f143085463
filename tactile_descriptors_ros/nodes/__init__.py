"""rclpy nodes: thin adapters between ROS 2 and the pure core.

* :mod:`.biotac_driver`   -- BioTac SPI (Cheetah), USB-serial bridge, simulated
  or loopback transport -> ``BioTacFrameBatch``; ``~/tare``; diagnostics.
* :mod:`.skin_driver`     -- skin cells over CAN (python-can) or serial
  (pyserial) -> ``SkinPartFrames`` (one per body part and batch); ``~/tare``; diagnostics.
* :mod:`.window_node`     -- frames -> contact gate -> windows -> ``Descriptor``.
* :mod:`.classifier_node` -- ``Descriptor`` + ``Label`` -> online PA-I -> ``Prediction``.

Every conversion between messages and core types lives in
:mod:`.conversions`; QoS parameters in :mod:`.qos`; the ``/diagnostics``
helper in :mod:`.diagnostics`.  Topics, parameters and services are listed in
``docs/nodes.md``.  Only rclpy APIs that exist since ROS 2 Humble are used.
"""

__all__: list[str] = []
