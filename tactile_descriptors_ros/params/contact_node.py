"""Parameters of ``contact_node``: frames -> contact per body part; rviz2 markers, tactile images (docs/view.md)."""

from __future__ import annotations

from ..topics import FRAMES_TOPIC
from .common import body_parts, diagnostics_period, frames_serialized, qos, robot, topic_pattern
from .schema import NodeSchema, Param, join

__all__ = ["CONTACT_NODE"]

#: a force no tactile sensor here measures [N]
_MAX_FORCE_N = 1000.0

CONTACT_NODE = NodeSchema("contact_node", join(
    robot(),
    body_parts("all body parts of the robot"),
    Param("contact.force_threshold_n", "double", "F_t: a cell at or above it is active, its body part in contact",
          robot="contact.force_threshold_n", unit="N", range=(0.0, _MAX_FORCE_N), tunable=True, apply="threshold"),
    Param("contact.floor_n", "double", "cells below this force carry none (their noise stays out of the total and "
          "the centre of pressure)", default=0.05, unit="N", range=(0.0, _MAX_FORCE_N), tunable=True,
          apply="floor"),
    Param("contact.lazy", "bool", "work out and publish tactile/<body part>/contact and wrench only while one of "
          "them has a subscriber (false: for every frames message, subscribed or not)", default=True, tunable=True,
          apply="lazy"),
    Param("view.rate_hz", "double", "display rate of markers, images and tactile/contacts (0 = none of them)",
          derived="the robot description's view.rate_hz", unit="Hz", range=(0.0, 1000.0)),
    Param("view.force_max_n", "double", "top of the colour scale", derived="the robot description's "
          "view.force_max_n", unit="N", range=(1e-3, _MAX_FORCE_N), tunable=True, apply="scale"),
    Param("view.stale_s", "double", "a cell with no valid sample this long is grey",
          derived="the robot description's view.stale_s", unit="s", range=(1e-3, 3600.0)),
    Param("view.image_size_px", "integer", "width and height of the tactile images", default=96, unit="px",
          range=(16, 1024)),
    Param("view.refresh_s", "double", "every marker and image is sent at least this often (in between only what "
          "changed)", default=1.0, unit="s", range=(0.0, 3600.0)),
    Param("view.markers", "bool", "publish tactile/<body part>/markers", default=True),
    Param("view.images", "bool", "publish tactile/<body part>/image", default=True),
    topic_pattern(FRAMES_TOPIC),
    frames_serialized(),
    Param("frames.drain_max", "integer", "frames taken from the queues per callback besides its own (0 = one per "
          "callback)", default=100, range=(0, 1_000_000), unit="messages", tunable=True, apply="drain"),
    diagnostics_period(),
    qos("frames", "best_effort", "volatile", 256),
    qos("contact", "reliable", "volatile", 10),
    qos("view", "reliable", "volatile", 10),
    qos("prediction", "reliable", "volatile", 50),
))
