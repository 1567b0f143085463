"""Parameters of ``tf_publisher``: the robot description's geometry on ``/tf_static`` (docs/view.md)."""

from __future__ import annotations

from .common import diagnostics_period, robot
from .schema import NodeSchema, Param, join

__all__ = ["TF_PUBLISHER"]

TF_PUBLISHER = NodeSchema("tf_publisher", join(
    robot(),
    Param("publish_links", "bool", "also publish the links' rest pose (no robot_state_publisher: simulation, bags)",
          default=True),
    Param("publish_sites", "bool", "also publish a frame per sensing site (BioTac electrodes)", default=True),
    diagnostics_period(),
))
