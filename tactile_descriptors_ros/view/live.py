"""``tactile view`` live: the running graph's ``tactile/contacts``, predictions, descriptors and labels.

One rclpy node (``tactile_view``) on its own executor thread.  It subscribes
to what the contact node publishes once per display period
(``ContactArray``, about 10 messages a second), not to the frames: the NAO's
700 frames messages a second would cost a viewer more CPU than the rest of
the view together (``docs/view.md``).  The contacts are taken best effort,
so a viewer that falls behind loses display frames instead of holding a
reliable publisher's history.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from ..core.robot import load_robot
from ..errors import ConfigError
from ..topics import CONTACTS_TOPIC, DESCRIPTOR_TOPIC, LABEL_TOPIC, PREDICTION_TOPIC
from .model import ViewModel

__all__ = ["LiveView"]


class LiveView:
    """Feed a :class:`~.model.ViewModel` from the live graph and publish its frames.

    Parameters
    ----------
    publish : callable
        ``publish(kind, payload)``: ``config`` once the robot is known (from
        ``robot`` or the first ``ContactArray``), then a ``frame`` per
        ``ContactArray``.
    robot : str, optional
        Robot name or YAML path; default: the ``robot`` the contacts name.
    context : rclpy.Context, optional
    namespace : str
        Namespace of the graph's topics.
    """

    def __init__(self, publish: Callable[[str, Any], None], *, robot: str | None = None, context: Any = None,
                 namespace: str = "") -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from tactile_descriptors_msgs.msg import ContactArray, Descriptor, Label, Prediction

        self.publish = publish
        self.model: ViewModel | None = None
        self.contact_arrays = 0
        self.error: str | None = None
        self._robot_arg = robot
        self.node = rclpy.create_node("tactile_view", namespace=namespace or None, context=context,
                                      start_parameter_services=False)
        best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.node.create_subscription(ContactArray, CONTACTS_TOPIC, self._on_contacts, best_effort)
        self.node.create_subscription(Prediction, PREDICTION_TOPIC, self._on_prediction, 50)
        self.node.create_subscription(Descriptor, DESCRIPTOR_TOPIC, self._on_descriptor, 50)
        self.node.create_subscription(Label, LABEL_TOPIC, self._on_label, 100)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread: threading.Thread | None = None
        self.changed = threading.Event()
        self._waiting = {"robot": "", "source": "live", "geometry": False, "parts": [], "force_max_n": 1.0,
                         "stale_s": 0.5, "rate_hz": 10.0, "colormap": "", "stale_rgb": [128, 128, 128],
                         "notice": f"waiting for {self.node.resolve_topic_name(CONTACTS_TOPIC)} "
                                   "(is the contact node running?)"}
        if robot:
            self._make_model(robot)
        else:
            publish("config", self._waiting)

    def config(self) -> dict:
        """The page's configuration: the robot's once known, else a notice that the view waits for it."""
        return self.model.config() if self.model is not None else self._waiting

    def _make_model(self, robot: str) -> None:
        self.model = ViewModel(load_robot(robot), source="live")
        self.publish("config", self.model.config())

    def start(self) -> LiveView:
        self._thread = threading.Thread(target=self._spin, daemon=True, name="tactile-view-ros")
        self._thread.start()
        return self

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception as exc:  # noqa: BLE001 - shutdown while spinning, or a real failure to report
            self.error = repr(exc)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    # ---------------------------------------------------------- callbacks
    def _on_contacts(self, msg) -> None:
        from ..nodes.contact_msgs import contact_from_msg

        if self.model is None:
            try:
                self._make_model(str(msg.robot))
            except ConfigError as exc:
                self.error = f"cannot load robot {msg.robot!r} named by the contacts: {exc} (give --robot)"
                return
        for c in msg.contacts:
            self.model.update_contact_msg(contact_from_msg(c))
        self.contact_arrays += 1
        self.publish("frame", self.model.frame())
        self.changed.set()

    def _on_prediction(self, msg) -> None:
        if self.model is not None:
            self.model.history.prediction(int(msg.exploration_id), _ns(msg.window_end), str(msg.class_name),
                                          list(msg.class_names), list(msg.scores), bool(msg.has_model))

    def _on_descriptor(self, msg) -> None:
        if self.model is not None:
            self.model.history.descriptor(int(msg.exploration_id), _ns(msg.window_end), list(msg.body_parts),
                                          list(msg.contact))

    def _on_label(self, msg) -> None:
        if self.model is not None:
            self.model.history.label(int(msg.exploration_id), str(msg.class_name))


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
