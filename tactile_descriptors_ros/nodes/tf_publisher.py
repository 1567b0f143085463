"""``tf_publisher``: the robot description's geometry on ``/tf_static``.

Publishes, once and latched (``transient_local``, as ``tf2_ros``'
``StaticTransformBroadcaster`` does), every frame the package's messages
name: the body parts' links in their rest pose (``publish_links``: for a
robot whose links no ``robot_state_publisher`` publishes, i.e. in
simulation and when replaying bags; leave it off on a robot that has one,
or the two would fight over the links), every cell's frame on its link and
every sensing site's frame on its cell (``publish_sites``).  A late
subscriber (rviz2, ``tactile record``) still gets the tree.

Frames and their names: ``docs/view.md``.
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.node import Node

from ..core.robot import load_robot
from ..errors import ConfigError
from ..params.tf_publisher import TF_PUBLISHER
from ..topics import TF_STATIC_TOPIC
from .common import Diagnostics, Status, StopsQuietly, run_node
from .contact_msgs import frames_to_tf_message
from .parameters import NodeParameters

__all__ = ["TfPublisher", "static_tf_qos", "main"]


def static_tf_qos():
    """tf2's static broadcaster QoS: reliable, transient local, depth 1."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


class TfPublisher(StopsQuietly, Node):
    """Publish the robot's static TF tree; ``kwargs`` go to :class:`rclpy.node.Node`."""

    def __init__(self, node_name: str = "tf_publisher", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        from tf2_msgs.msg import TFMessage

        self.params = params = NodeParameters(self, TF_PUBLISHER)
        robot_arg = params.declare("robot")
        if not robot_arg:
            raise ConfigError("parameter 'robot' is required (e.g. shadow_hand, nao or a YAML path)", key="robot")
        self.robot = load_robot(robot_arg)
        if self.robot.geometry is None:
            raise ConfigError(f"robot {self.robot.name!r} has no geometry section: no frames to publish "
                              "(docs/view.md)", key="robot", source=self.robot.source)
        params.declare_all(robot=self.robot)
        links, sites = params["publish_links"], params["publish_sites"]
        self.frames = self.robot.geometry.frames(self.robot, links=links, sites=sites)
        self.pub = self.create_publisher(TFMessage, TF_STATIC_TOPIC, static_tf_qos())
        self.pub.publish(frames_to_tf_message(self.frames, self.get_clock().now().nanoseconds))
        self.diagnostics = Diagnostics(self, params["diagnostics_period_s"])
        self.diagnostics.add("frames", lambda: Status("ok", f"{len(self.frames)} static frames under "
                                                            f"{self.robot.geometry.root_frame}",
                                                      {"frames": len(self.frames), "links": links, "sites": sites}))
        params.finish()
        self.get_logger().info(f"robot {self.robot.name}: {len(self.frames)} static frames under "
                               f"{self.robot.geometry.root_frame} on {TF_STATIC_TOPIC}"
                               + ("" if links else " (links left to robot_state_publisher)"))


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``tf_publisher`` executable."""
    return run_node(TfPublisher, args)


if __name__ == "__main__":
    raise SystemExit(main())
