"""An rviz2 configuration of a robot's tactile view: TF, each body part's markers and tactile image (no ROS).

``tactile rviz ROBOT`` writes it; the shipped ``config/rviz/<robot>.rviz``
are its output (a test keeps them equal).  Every display subscribes with
rviz2's default QoS (reliable, volatile, depth 5), which the contact node's
publishers (reliable, volatile) match; the fixed frame is the robot's root.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import yaml

from ..core.robot import RobotDescription
from ..errors import ConfigError
from ..topics import IMAGE_TOPIC, MARKERS_TOPIC, absolute

__all__ = ["rviz_config", "rviz_text", "RVIZ_QOS"]

#: rviz2's default subscription QoS of a display.
RVIZ_QOS = {"Depth": 5, "Durability Policy": "Volatile", "History Policy": "Keep Last",
            "Reliability Policy": "Reliable"}


def _topic(name: str) -> dict[str, Any]:
    return {**RVIZ_QOS, "Value": name}


def rviz_config(robot: RobotDescription) -> dict[str, Any]:
    """The configuration as data (what rviz2 reads from YAML)."""
    geo = robot.geometry
    if geo is None:
        raise ConfigError(f"robot {robot.name!r} has no geometry section: rviz2 has nothing to place",
                          key="geometry", source=robot.source)
    displays: list[dict[str, Any]] = [
        {"Class": "rviz_default_plugins/Grid", "Name": "Grid", "Enabled": True, "Cell Size": 0.05,
         "Plane Cell Count": 20, "Reference Frame": "<Fixed Frame>", "Value": True},
        {"Class": "rviz_default_plugins/TF", "Name": "TF", "Enabled": True, "Show Names": False, "Show Axes": True,
         "Marker Scale": 0.05, "Frame Timeout": 15, "Value": True},
    ]
    for part in robot.body_parts:
        displays.append({"Class": "rviz_default_plugins/MarkerArray", "Name": f"{part.name} markers",
                         "Enabled": True, "Namespaces": {}, "Topic": _topic(absolute(MARKERS_TOPIC.format(
                             body_part=part.name))), "Value": True})
    for part in robot.body_parts:
        displays.append({"Class": "rviz_default_plugins/Image", "Name": f"{part.name} image", "Enabled": True,
                         "Max Value": 1, "Min Value": 0, "Median window": 5, "Normalize Range": False,
                         "Topic": _topic(absolute(IMAGE_TOPIC.format(body_part=part.name))), "Value": True})
    points = np.array([geo.rest_pose(geo.cell_frames[c.id], robot).xyz for p in robot.body_parts for c in p.cells])
    centre = points.mean(axis=0)
    extent = float(np.ptp(points, axis=0).max())
    return {
        "Panels": [{"Class": "rviz_common/Displays", "Name": "Displays", "Help Height": 0,
                    "Tree Height": 500}],
        "Visualization Manager": {
            "Class": "", "Name": "root", "Enabled": True, "Displays": displays,
            "Global Options": {"Background Color": "48; 48; 48", "Fixed Frame": geo.root_frame, "Frame Rate": 30},
            "Tools": [{"Class": "rviz_default_plugins/Interact"}, {"Class": "rviz_default_plugins/MoveCamera"}],
            "Views": {"Current": {"Class": "rviz_default_plugins/Orbit", "Name": "Current View",
                                  "Distance": round(max(0.2, 2.5 * extent), 3),
                                  "Focal Point": {"X": round(float(centre[0]), 4), "Y": round(float(centre[1]), 4),
                                                  "Z": round(float(centre[2]), 4)},
                                  "Pitch": 0.5, "Yaw": 0.8, "Target Frame": "<Fixed Frame>", "Value": "Orbit (rviz)"},
                      "Saved": None},
        },
        "Window Geometry": {"Height": 900, "Width": 1400, "Displays": {"collapsed": False}},
    }


def rviz_text(robot: RobotDescription) -> str:
    """The configuration as an ``.rviz`` file's text."""
    head = (f"# rviz2 view of {robot.name}'s skin: written by `tactile rviz {robot.name}` (docs/view.md).\n"
            f"# rviz2 -d <this file>, with the graph running (the contact node publishes the markers and images).\n")
    return head + yaml.safe_dump(rviz_config(robot), sort_keys=False, default_flow_style=False)
