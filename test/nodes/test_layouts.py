"""Descriptor layouts: the labels travel once per layout (latched), each Descriptor names its layout by id."""

from __future__ import annotations

import hashlib
import types

import numpy as np
import pytest
from node_helpers import BiotacStream, spin_until

from tactile_descriptors_ros.layouts import DescriptorLayouts, layout_id


def _layout(labels, lid=None):
    return types.SimpleNamespace(labels=list(labels), layout_id=lid or layout_id(labels))


def _descriptor(lid, labels=()):
    return types.SimpleNamespace(layout_id=lid, labels=list(labels))


def test_layout_id_is_the_sha256_of_the_labels():
    labels = ["index/paper/A_S", "index/paper/M_S"]
    assert layout_id(labels) == hashlib.sha256(b"index/paper/A_S\nindex/paper/M_S\n").hexdigest()[:16]
    assert layout_id(labels) != layout_id(labels[::-1]) != layout_id(labels[:1])


def test_layouts_resolve_hold_and_expire():
    a, b = ["x/1", "x/2"], ["y/1"]
    lay = DescriptorLayouts(max_held=2, wait_s=5.0)
    own = _descriptor("whatever", labels=["z/1"])
    assert lay.of(own) == ("z/1",)  # a descriptor with its own labels needs no layout
    early = _descriptor(layout_id(a))
    assert lay.of(early) is None
    lay.hold(early, now_s=0.0)
    assert lay.add(_layout(a)) == [early] and lay.of(early) == tuple(a) and lay.held == 0
    late = [_descriptor(layout_id(b)) for _ in range(3)]
    for k, d in enumerate(late):
        lay.hold(d, now_s=float(k))
    assert lay.held == 2 and lay.unknown == 1  # at most max_held wait: the oldest is dropped, counted
    assert lay.expire(now_s=6.5) == [late[1]] and lay.unknown == 2 and lay.held == 1
    assert lay.add(_layout(b, lid="0" * 16)) == [] and lay.bad == 1  # an id that is not its labels' is refused
    assert lay.of(late[2]) is None


def _window_node_and_io(ros_context):
    """A Shadow Hand window node taking reliable frames, and a node ``io`` that publishes the index finger's frames
    (``pub``) and collects the descriptors (``got``); both in ``ex``, once matched and the kernel ready."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    w = WindowNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="shadow_hand"), Parameter("qos.frames.reliability", value="reliable")])
    io = rclpy.create_node("io", context=ros_context)
    got: list = []
    io.create_subscription(Descriptor, "tactile/descriptor", got.append, 10)
    pub = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(w)
    ex.add_node(io)
    return w, io, got, pub, ex


@pytest.mark.ros
def test_the_window_node_latches_the_layout_and_sends_descriptors_without_labels(ros_context):
    """A subscriber that starts after the first descriptor still gets the layout (transient local); a
    descriptor names it by id, and carries about a quarter of the bytes it did with the labels inline."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message

    from tactile_descriptors_msgs.msg import Descriptor, DescriptorLayout

    w, io, got, pub, ex = _window_node_and_io(ros_context)
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1 and w.kernel_ready.is_set(), 60)
        for m in BiotacStream().exploration(40.0):
            pub.publish(m)
            ex.spin_once(timeout_sec=0.005)
        assert spin_until(ex, lambda: got, 30)
        late: list = []
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        io.create_subscription(DescriptorLayout, "tactile/descriptor_layout", late.append, latched)
        assert spin_until(ex, lambda: late, 30), "a late subscriber did not get the latched layout"
        d, lay = got[0], late[0]
        assert list(d.labels) == [] and d.layout_id == lay.layout_id == layout_id(lay.labels)
        assert len(lay.labels) == len(d.values) == 5 * 261 and lay.labels[261] == "index/per_channel/A_pac"
        assert d.header.frame_id == lay.header.frame_id == "forearm"  # the Shadow Hand's root frame
        assert (lay.robot, lay.layout_mode, list(lay.body_parts)) == ("shadow_hand", "concat", list(d.body_parts))
        inline = Descriptor()
        for field in Descriptor.get_fields_and_field_types():
            setattr(inline, field, getattr(d, field))
        inline.labels = list(lay.labels)
        sizes = len(serialize_message(d)), len(serialize_message(inline))
        assert sizes[0] < 0.3 * sizes[1], sizes
        print(f"Descriptor of the Shadow Hand: {sizes[0]} bytes, {sizes[1]} with its labels inline")
    finally:
        ex.shutdown()
        w.destroy_node()
        io.destroy_node()


@pytest.mark.ros
def test_the_window_node_announces_its_layout_at_its_first_frames(ros_context):
    """At its first frames the window node rehearses its describing path (a window of noise, described, not
    published) and publishes the layout then: a classifier holds the labels before the first descriptor, which
    names that same layout; one layout message in all."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import DescriptorLayout

    w, io, got, pub, ex = _window_node_and_io(ros_context)
    layouts: list = []
    io.create_subscription(DescriptorLayout, "tactile/descriptor_layout", layouts.append,
                           QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                      durability=DurabilityPolicy.TRANSIENT_LOCAL))
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1 and w.kernel_ready.is_set(), 60)
        stream = BiotacStream()
        pub.publish(stream.batch(2.0, 40.0))  # 0.1 s of frames: no window closes
        assert spin_until(ex, lambda: layouts, 30), "no layout at the first frames"
        assert w.rehearsal_ms is not None and w.frames_taken == 1 and w.descriptors_published == 0 and not got
        for m in stream.exploration(40.0):
            pub.publish(m)
            ex.spin_once(timeout_sec=0.005)
        assert spin_until(ex, lambda: got, 30)
        assert [lay.layout_id for lay in layouts] == [got[0].layout_id] == [layout_id(layouts[0].labels)]
        assert len(w.layouts_published) == 1
    finally:
        ex.shutdown()
        w.destroy_node()
        io.destroy_node()


@pytest.mark.ros
def test_the_classifier_waits_for_a_layout_and_names_the_descriptors_frame(ros_context, tmp_path):
    """A descriptor that arrives before its layout is predicted once the layout comes; one whose layout never
    comes is dropped after its wait, counted and reported; predictions carry the descriptor's frame_id."""
    import rclpy
    from descriptor_msgs import LABELS, descriptor_msg
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, DescriptorLayout, Prediction
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    c = ClassifierNode(context=ros_context, parameter_overrides=[
        Parameter("model_path", value=str(tmp_path / "m.json")), Parameter("label_wait_s", value=0.0)])
    c.layouts.wait_s = 0.2
    io = rclpy.create_node("io", context=ros_context)
    preds: list = []
    io.create_subscription(Prediction, "tactile/prediction", preds.append, 10)
    desc_pub = io.create_publisher(Descriptor, "tactile/descriptor", 10)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    layout_pub = io.create_publisher(DescriptorLayout, "tactile/descriptor_layout", latched)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(c)
    ex.add_node(io)
    rng = np.random.default_rng(0)
    try:
        assert spin_until(ex, lambda: desc_pub.get_subscription_count() >= 1 and
                          layout_pub.get_subscription_count() >= 1 and c.pub.get_subscription_count() >= 1, 30)
        first = descriptor_msg(1, rng)
        first.labels, first.layout_id = [], layout_id(LABELS)
        first.header.frame_id = "hand_base"
        desc_pub.publish(first)
        assert spin_until(ex, lambda: c.layouts.held == 1, 10)
        assert not preds
        layout_pub.publish(DescriptorLayout(layout_id=layout_id(LABELS), labels=LABELS))
        assert spin_until(ex, lambda: preds, 10), "the held descriptor was not predicted once its layout came"
        assert preds[0].exploration_id == 1 and preds[0].header.frame_id == "hand_base"
        orphan = descriptor_msg(2, rng)
        orphan.labels, orphan.layout_id = [], "f" * 16
        desc_pub.publish(orphan)
        assert spin_until(ex, lambda: c.layouts.unknown == 1, 10)
        status = c.diagnostics.statuses()[0]
        assert status.message.startswith("1 descriptors whose layout never came"), status.message
        assert len(preds) == 1
    finally:
        ex.shutdown()
        c.close()
        c.destroy_node()
        io.destroy_node()
