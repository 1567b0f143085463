"""Every message imports in rclpy and crosses a real topic unchanged."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_messages_round_trip_through_serialization(ros_message_examples):
    from rclpy.serialization import deserialize_message, serialize_message

    for msg in ros_message_examples:
        back = deserialize_message(serialize_message(msg), type(msg))
        assert back == msg


def test_messages_cross_a_real_topic(ros_context, ros_message_examples):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    examples = ros_message_examples
    node = rclpy.create_node("msg_roundtrip", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    received: dict[str, list] = {}
    pubs = []
    for i, msg in enumerate(examples):
        topic = f"roundtrip_{i}"
        received[topic] = []
        node.create_subscription(type(msg), topic, received[topic].append, 10)
        pubs.append((node.create_publisher(type(msg), topic, 10), msg, topic))
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not all(received.values()):
        for pub, msg, topic in pubs:
            if not received[topic]:
                pub.publish(msg)
        executor.spin_once(timeout_sec=0.05)
    node.destroy_node()
    executor.shutdown()
    for _pub, msg, topic in pubs:
        assert received[topic], f"{type(msg).__name__} never arrived"
        got = received[topic][0]
        assert got == msg
    d = received["roundtrip_2"][0]
    np.testing.assert_allclose(np.asarray(d.values), [1234.5, 287.25])
    assert received["roundtrip_0"][0].pac[3] == 65535
