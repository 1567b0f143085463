"""What the message definitions and the shipped robot files say in their comments matches what the nodes do."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _comment(msg_file: str, field: str) -> str:
    """The comment on the line of ``field`` in a .msg file, with its continuation lines."""
    lines = (REPO / "msg" / "msg" / msg_file).read_text().splitlines()
    for i, line in enumerate(lines):
        if re.match(rf"^[A-Za-z][\w/\[\]]* {field}\b", line):
            text = line.split("#", 1)[1] if "#" in line else ""
            for more in lines[i + 1:]:
                if not more.lstrip().startswith("#") or not more.startswith(" "):
                    break
                text += " " + more.split("#", 1)[1]
            return text.strip()
    raise AssertionError(f"no field {field} in {msg_file}")


def test_descriptor_comments_name_what_the_window_node_sends():
    from tactile_descriptors_ros.core.groups import selection_name
    from tactile_descriptors_ros.core.robot import load_robot

    shipped = selection_name(load_robot("shadow_hand").descriptor.groups)
    assert f'"{shipped}"' in _comment("Descriptor.msg", "channel_mode")
    assert "DescriptorLayout" in _comment("Descriptor.msg", "layout_id")
    assert "empty" in _comment("Descriptor.msg", "labels")
    from tactile_descriptors_ros.params.classifier_node import CLASSIFIER_NODE

    update = {"arow": "AROW", "max_loss": "Crammer et al.'s max-loss update", "prediction": "PA-I"}
    shipped_update = update[CLASSIFIER_NODE["pa_update"].default]
    assert f"by default {shipped_update}" in (REPO / "msg" / "msg" / "Prediction.msg").read_text()
    assert "descriptor's" in _comment("Prediction.msg", "header")


def test_robot_files_name_the_default_model_file_the_classifier_uses():
    for robot in ("shadow_hand", "nao"):
        text = (REPO / "config" / f"{robot}.yaml").read_text()
        for path in re.findall(r"#.*?(\$ROS_HOME/\S+\.json)", text):
            assert path == f"$ROS_HOME/tactile_descriptors_ros/{robot}/classifier_node.json", (robot, path)
