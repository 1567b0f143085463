"""Every message imports in rclpy and crosses a real topic unchanged."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def _examples():
    from builtin_interfaces.msg import Time
    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor, Label, Prediction, SkinCellFrame

    b = BioTacFrameBatch()
    b.header.stamp = Time(sec=12, nanosec=345)
    b.header.frame_id = "index_biotac"
    b.sensor_name, b.body_part, b.serial_number = "biotac_index", "index", "BT0042"
    b.chip_select, b.first_frame_sequence, b.frame_count, b.electrode_count = 1, 7, 2, 19
    b.pac = list(range(44))
    b.pac[3] = BioTacFrameBatch.INVALID_COUNT
    b.pac_offset_ns = [i * 454_545 for i in range(44)]
    b.frame_offset_ns = [0, 10_000_000]
    b.pdc, b.tac, b.tdc = [100, 101], [2000, 2001], [1500, 1501]
    b.electrodes = list(range(38))
    b.pac_pa_per_count, b.force_n_per_count, b.pdc_tare_counts = 0.37, 0.05, 1980.0
    b.electrode_tare_counts = [float(i) for i in range(19)]
    b.bad_words = 1

    s = SkinCellFrame()
    s.cell_id, s.body_part, s.sequence = 17, "chest", 99
    s.accel_x, s.accel_y, s.accel_z = [-512, 0, 511, SkinCellFrame.INVALID_ACCEL], [1, 2, 3, 4], [5, 6, 7, 8]
    s.accel_offset_ns = [0, 1_000_000, 2_000_000, 3_000_000]
    s.force = [1, 2, 3]
    s.force_offset_ns = [0]
    s.force_tare_counts = [1.0, 2.0, 3.0]
    s.proximity = [400]
    s.temperature_c = 31.5

    d = Descriptor()
    d.robot, d.exploration_id = "shadow_hand", 5
    d.window_mode, d.layout_mode, d.channel_mode = Descriptor.WINDOW_EXPLORATION, Descriptor.MODE_CONCAT, \
        Descriptor.CHANNELS_AVERAGED
    d.body_parts, d.contact, d.cells_in_contact, d.cells_total = ["thumb", "index"], [False, True], [0, 1], [1, 1]
    d.mean_force_n = [0.0, 1.5]
    d.quality = [Descriptor.QUALITY_NO_CONTACT, 0]
    d.labels = ["index/A_pac", "index/M_pac"]
    d.values = [1234.5, 287.25]

    p = Prediction()
    p.exploration_id, p.has_model, p.class_name = 5, True, "cork"
    p.class_names, p.scores, p.model_version, p.updates = ["cork", "felt"], [0.5, -0.5], 3, 3

    lab = Label()
    lab.exploration_id, lab.class_name = 5, "cork"
    return [b, s, d, p, lab]


def test_messages_round_trip_through_serialization():
    from rclpy.serialization import deserialize_message, serialize_message

    for msg in _examples():
        back = deserialize_message(serialize_message(msg), type(msg))
        assert back == msg


def test_messages_cross_a_real_topic(ros_context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    examples = _examples()
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
    for pub, msg, topic in pubs:
        assert received[topic], f"{type(msg).__name__} never arrived"
        got = received[topic][0]
        assert got == msg
    d = received["roundtrip_2"][0]
    np.testing.assert_allclose(np.asarray(d.values), [1234.5, 287.25])
    assert received["roundtrip_0"][0].pac[3] == 65535
