"""contact_node through real topics: Contact, WrenchStamped, rviz2 markers and tactile images at known forces."""

from __future__ import annotations

import time

import numpy as np
import pytest
from node_helpers import BiotacStream, spin_until

from tactile_descriptors_ros.core.colormap import STALE_RGB, force_colours
from tactile_descriptors_ros.core.robot import load_robot

pytestmark = pytest.mark.ros

PRESSED = {90: 1.0, 91: 0.5}  # chest cells and their forces [N]
TARE = 20.0  # counts


def _rviz_qos():
    """rviz2's default display subscription: reliable, volatile, keep last 5."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def _chest_frames(t_ns: int, seq: int):
    """One SkinPartFrames of the NAO's chest: every cell 2 force and 8 accelerometer samples, PRESSED pressed."""
    from tactile_descriptors_msgs.msg import SkinPartFrames

    robot = load_robot("nao")
    ids = [c.id for c in robot.body_part("chest").cells]
    n_per = robot.cell_types["skin_cell"].force.n_per_count
    msg = SkinPartFrames()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
    msg.header.frame_id, msg.body_part = "torso", "chest"
    msg.cell_ids = ids
    msg.sequence = [seq] * len(ids)
    msg.accel_count = [8] * len(ids)
    msg.force_count = [2] * len(ids)
    msg.temperature_c = [30.0] * len(ids)
    msg.force_tare_counts = [TARE] * (3 * len(ids))
    msg.bad_frames = [0] * len(ids)
    rng = np.random.default_rng(seq)
    msg.accel_x = rng.integers(-20, 20, 8 * len(ids)).astype(np.int16).tolist()
    msg.accel_y = [0] * (8 * len(ids))
    msg.accel_z = [256] * (8 * len(ids))
    msg.accel_offset_ns = [k * 1_000_000 for _ in ids for k in range(8)]
    force = []
    for cid in ids:
        counts = int(round(TARE + PRESSED.get(cid, 0.0) / n_per))
        force += [counts] * 6
    msg.force = force
    msg.force_offset_ns = [k * 4_000_000 for _ in ids for k in range(2)]
    msg.accel_mps2_per_count, msg.force_n_per_count = 0.0383072, n_per
    return msg


def _chest_node(ros_context, **params):
    """A contact node of the NAO's chest alone, called directly (no executor), with ``params`` (dotted names
    spelt with ``__``: ``view__rate_hz``)."""
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.contact_node import ContactNode

    return ContactNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="nao"), Parameter("body_parts", value=["chest"]),
        *(Parameter(k.replace("__", "."), value=v) for k, v in params.items())])


def _feed(node, n: int, t_ns: int, seq: int) -> tuple[int, int]:
    """``n`` chest messages 10 ms apart into the node's frames callback; the next stamp and batch number."""
    for _ in range(n):
        node._on_frames(_chest_frames(t_ns, seq))
        t_ns, seq = t_ns + 10_000_000, seq + 1
    return t_ns, seq


@pytest.fixture
def graph(ros_context):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import Image
    from visualization_msgs.msg import MarkerArray

    from tactile_descriptors_msgs.msg import Contact, ContactArray, SkinPartFrames
    from tactile_descriptors_ros.nodes.contact_node import ContactNode

    # stale_s long: on a loaded machine this test's feed can pause for longer than the shipped 0.5 s, which would
    # grey the cells (staleness is test_display_keeps_a_cells_last_force_and_greys_stale_ones' in test/core)
    node = ContactNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="nao"), Parameter("body_parts", value=["chest"]),
        Parameter("qos.frames.reliability", value="reliable"), Parameter("view.stale_s", value=30.0)])
    io = rclpy.create_node("contact_test_io", context=ros_context)
    got: dict[str, list] = {k: [] for k in ("contact", "wrench", "markers", "image", "contacts")}
    io.create_subscription(Contact, "tactile/chest/contact", got["contact"].append, 50)
    io.create_subscription(WrenchStamped, "tactile/chest/wrench", got["wrench"].append, 50)
    io.create_subscription(MarkerArray, "tactile/chest/markers", got["markers"].append, _rviz_qos())
    io.create_subscription(Image, "tactile/chest/image", got["image"].append, _rviz_qos())
    io.create_subscription(ContactArray, "tactile/contacts", got["contacts"].append, 10)
    pub = io.create_publisher(SkinPartFrames, "tactile/chest/frames", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(io)
    try:
        yield node, io, ex, pub, got
    finally:
        ex.shutdown()
        node.destroy_node()
        io.destroy_node()


def _shown(arrays) -> dict:
    """What rviz2 shows after these MarkerArrays: the latest marker per (namespace, id), deleted ones included."""
    out = {}
    for arr in arrays:
        for m in arr.markers:
            out[(m.ns, m.id)] = m
    return out


def _feed_until(ex, pub, cond, timeout_s=30.0, start_ns=5_000_000_000):
    """Publish a chest message every 20 ms (sensor time advancing 10 ms each) until ``cond()``."""
    t, seq = start_ns, 0
    deadline = time.monotonic() + timeout_s
    last = 0.0
    while time.monotonic() < deadline and not cond():
        if time.monotonic() - last > 0.02:
            pub.publish(_chest_frames(t, seq))
            t, seq, last = t + 10_000_000, seq + 1, time.monotonic()
        ex.spin_once(timeout_sec=0.01)
    return cond()


def test_contact_and_wrench_at_the_frame_rate(graph):
    node, io, ex, pub, got = graph
    assert _feed_until(ex, pub, lambda: len(got["contact"]) >= 3 and len(got["wrench"]) >= 3)
    robot = load_robot("nao")
    tax = robot.geometry.taxels(robot, "chest")
    c = got["contact"][-1]
    assert c.header.frame_id == "torso" and c.body_part == "chest" and c.in_contact
    assert c.force_n == pytest.approx(1.5, abs=0.01)
    assert sorted(c.active_cell_ids) == [90, 91]
    ids = list(tax.cell_ids)
    expect = (1.0 * tax.positions[ids.index(90)] + 0.5 * tax.positions[ids.index(91)]) / 1.5
    cop = np.array([c.centre_of_pressure.x, c.centre_of_pressure.y, c.centre_of_pressure.z])
    assert np.allclose(cop, expect, atol=2e-4)  # the forces' rounding to counts
    assert np.allclose([c.normal.x, c.normal.y, c.normal.z], [1.0, 0.0, 0.0])
    assert np.asarray(c.cell_force_n)[ids.index(90)] == pytest.approx(1.0, abs=0.002)
    assert c.vibration_unit == "m/s^2" and c.vibration_rms > 0
    # one contact per frames message: its window is the message's force samples
    assert (c.header.stamp.sec * 10**9 + c.header.stamp.nanosec) - \
        (c.window_start.sec * 10**9 + c.window_start.nanosec) == 4_000_000
    w = got["wrench"][-1]
    assert w.header.frame_id == "torso"
    f = np.array([w.wrench.force.x, w.wrench.force.y, w.wrench.force.z])
    tau = np.array([w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z])
    assert np.allclose(f, [-1.5, 0, 0], atol=0.01) and np.allclose(tau, np.cross(cop, f), atol=1e-5)


@pytest.mark.parametrize("host_clock", [True, False])
def test_contact_age_is_timed_on_host_stamps_and_counted_on_device_stamps(graph, host_clock):
    """Frames stamped on the host clock give ``contact_age_ms``; frames on another clock (the simulator's scene
    time, 5 s after 1970 here) are counted in ``contacts_not_host_time`` and never timed as a 56-year age."""
    node, io, ex, pub, got = graph
    start_ns = time.time_ns() - 200_000_000 if host_clock else 5_000_000_000
    assert _feed_until(ex, pub, lambda: len(got["contact"]) >= 3, start_ns=start_ns)
    values = node._status().values
    if host_clock:
        assert values["contacts_not_host_time"] == 0, values
        assert 0.0 < values["contact_age_ms_p50"] < 60_000.0, values
    else:
        assert values["contacts_not_host_time"] >= 3, values
        assert "contact_age_ms_p50" not in values and "contact_age_ms_max" not in values, values


def test_markers_and_image_show_known_forces_in_viridis(graph):
    node, io, ex, pub, got = graph
    from visualization_msgs.msg import Marker

    assert _feed_until(ex, pub, lambda: len(got["markers"]) >= 3 and len(got["image"]) >= 2)
    robot = load_robot("nao")
    ids = [c.id for c in robot.body_part("chest").cells]
    markers = list(_shown(got["markers"]).values())
    cells = sorted((m for m in markers if m.ns == "cells"), key=lambda m: m.id)
    assert len(cells) == 32 and all(m.header.frame_id == "torso" and m.type == Marker.CYLINDER for m in cells)
    for cid in ids:
        m = cells[ids.index(cid)]
        rgb = np.rint(np.array([m.color.r, m.color.g, m.color.b]) * 255)
        assert np.array_equal(rgb, force_colours([PRESSED.get(cid, 0.0)], 2.0)[0]), cid
    point = next(m for m in markers if m.ns == "contact_point")
    arrow = next(m for m in markers if m.ns == "contact_normal")
    assert point.action == Marker.ADD and arrow.action == Marker.ADD and len(arrow.points) == 2
    assert next(m for m in markers if m.ns == "prediction").action == Marker.DELETE  # no prediction yet
    img = got["image"][-1]
    assert img.encoding == "rgb8" and img.header.frame_id == "torso" and (img.width, img.height) == (96, 96)
    pixels = np.frombuffer(bytes(img.data), np.uint8).reshape(img.height, img.width, 3)
    colours = {tuple(force_colours([f], 2.0)[0]) for f in (1.0, 0.5, 0.0)}
    seen = {tuple(p) for p in pixels.reshape(-1, 3)}
    assert colours <= seen and tuple(STALE_RGB) not in seen
    arr = got["contacts"][-1]
    assert arr.robot == "nao" and arr.header.frame_id == "base_link" and [c.body_part for c in arr.contacts] == ["chest"]


def test_prediction_text_stands_at_the_body_part_that_touched(graph):
    node, io, ex, pub, got = graph
    from visualization_msgs.msg import Marker

    from tactile_descriptors_msgs.msg import Descriptor, Prediction

    dpub = io.create_publisher(Descriptor, "tactile/descriptor", 10)
    ppub = io.create_publisher(Prediction, "tactile/prediction", 10)
    d = Descriptor(robot="nao", exploration_id=4, body_parts=["chest", "left_hand"], contact=[True, False])
    d.window_end.sec = 5
    p = Prediction(exploration_id=4, has_model=True, class_name="felt", class_names=["cork", "felt"],
                   scores=[-1.0, 1.0])
    p.window_end.sec = 5

    def text():
        label = _shown(got["markers"]).get(("prediction", 0))
        return label.text if label is not None and label.action == Marker.ADD else ""

    def ready():
        if node.count_publishers("tactile/descriptor") and node.count_publishers("tactile/prediction"):
            dpub.publish(d)
            ppub.publish(p)
        return text().startswith("felt")

    assert _feed_until(ex, pub, ready)
    assert text() == f"felt {100 / (1 + np.exp(-2.0)):.0f}%"


def test_biotac_electrodes_share_the_force_and_locate_it(ros_context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Contact
    from tactile_descriptors_ros.nodes.contact_node import ContactNode

    node = ContactNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="shadow_hand"), Parameter("body_parts", value=["index"]),
        Parameter("qos.frames.reliability", value="reliable")])
    io = rclpy.create_node("contact_test_biotac", context=ros_context)
    got = []
    io.create_subscription(Contact, "tactile/index/contact", got.append, 50)
    pub = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(io)
    stream = BiotacStream()
    try:
        def send():
            msg = stream.batch(1.5, 80.0)
            el = np.asarray(msg.electrodes, dtype=np.int64).reshape(-1, 19)
            el[:, 9] += 200  # e10 pressed
            msg.electrodes = el.ravel().astype(np.uint16).tolist()
            msg.electrode_tare_counts = [1500.0] * 19  # the stream's electrode baseline
            pub.publish(msg)
            return bool(got)

        assert spin_until(ex, send, 20.0)
        c = got[-1]
        robot = load_robot("shadow_hand")
        tax = robot.geometry.taxels(robot, "index")
        assert c.header.frame_id == "ffdistal" and c.in_contact and c.force_n == pytest.approx(1.5, abs=0.06)
        assert list(c.site_names) == list(tax.names)
        share = np.asarray(c.site_force_n)
        assert np.argmax(share) == 9 and share.sum() == pytest.approx(c.force_n, rel=1e-5)
        cop = np.array([c.centre_of_pressure.x, c.centre_of_pressure.y, c.centre_of_pressure.z])
        assert np.linalg.norm(cop - tax.positions[9]) < 0.001
    finally:
        ex.shutdown()
        node.destroy_node()
        io.destroy_node()


def test_a_robot_without_geometry_is_refused_at_start(ros_context, tmp_path):
    import yaml
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.core.robot import robot_config_path
    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.nodes.contact_node import ContactNode

    data = yaml.safe_load(robot_config_path("shadow_hand").read_text())
    del data["geometry"], data["cell_types"]["biotac"]["sites"]
    for part in data["body_parts"]:
        del part["link"]
        for cell in part["cells"]:
            del cell["xyz"], cell["rpy"]
    path = tmp_path / "bare.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match="no geometry section"):
        ContactNode(context=ros_context, parameter_overrides=[Parameter("robot", value=str(path))])


def test_markers_carry_what_changed_and_every_marker_when_full():
    """rviz2 keeps a marker until replaced: an update sends only what changed, a full one everything."""
    from visualization_msgs.msg import Marker

    from tactile_descriptors_ros.core.contact import ContactEstimate
    from tactile_descriptors_ros.core.display import DisplayFrame
    from tactile_descriptors_ros.nodes.contact_msgs import MarkerStyle, PartMarkers

    robot = load_robot("nao")
    tax = robot.geometry.taxels(robot, "chest")
    n = len(tax)
    pm = PartMarkers(tax, MarkerStyle.of(tax))

    def frame(forces, stale=()):
        forces = np.asarray(forces, dtype=float)
        stale_mask = np.isin(np.arange(n), list(stale))
        total = float(forces.sum())
        cop = (forces[:, None] * tax.positions).sum(axis=0) / total if total else np.zeros(3)
        est = ContactEstimate(bool((forces >= 0.2).any()), total, cop, np.array([1.0, 0, 0]) if total else np.zeros(3),
                              forces, forces, tax.cell_ids[forces >= 0.2], 0.0)
        return DisplayFrame(est, stale_mask, stale_mask, 0, 1)

    def keys(arr):
        return [(m.ns, m.id) for m in arr.markers]

    idle = np.zeros(n)
    first = pm.update(frame(idle), stamp_ns=1, force_max_n=2.0)
    assert len(first.markers) == n + 3  # the cells, the contact point and normal (deleted), the text (deleted)
    assert pm.update(frame(idle), stamp_ns=2, force_max_n=2.0) is None  # nothing changed: nothing to send
    full = pm.update(frame(idle), stamp_ns=3, force_max_n=2.0, full=True)
    assert keys(full) == keys(first) and all(m.header.stamp.nanosec == 3 for m in full.markers)
    pressed = idle.copy()
    pressed[[4, 5]] = [1.0, 0.5]
    arr = pm.update(frame(pressed), stamp_ns=4, force_max_n=2.0)
    assert keys(arr) == [("cells", 4), ("cells", 5), ("contact_point", 0), ("contact_normal", 0)]
    rgb = np.rint([[m.color.r * 255, m.color.g * 255, m.color.b * 255] for m in arr.markers[:2]])
    assert np.array_equal(rgb, force_colours([1.0, 0.5], 2.0))
    assert arr.markers[2].action == Marker.ADD and arr.markers[3].action == Marker.ADD
    arr = pm.update(frame(pressed, stale=[9]), stamp_ns=5, force_max_n=2.0, text="cork 80%")
    assert keys(arr) == [("cells", 9), ("prediction", 0)] and arr.markers[1].text == "cork 80%"
    assert (arr.markers[0].color.r * 255, arr.markers[0].color.g * 255) == pytest.approx(STALE_RGB[:2])
    arr = pm.update(frame(idle), stamp_ns=6, force_max_n=2.0, text="cork 80%")
    assert keys(arr) == [("cells", 4), ("cells", 5), ("cells", 9), ("contact_point", 0), ("contact_normal", 0)]
    assert arr.markers[3].action == Marker.DELETE and arr.markers[4].action == Marker.DELETE
    # what rviz2 shows after the partial arrays is what one full array shows
    shown = _shown([first, arr])
    for m in pm.update(frame(idle), stamp_ns=7, force_max_n=2.0, text="cork 80%", full=True).markers:
        s = shown.get((m.ns, m.id))
        assert s is not None and (s.action, s.color, s.text) == (m.action, m.color, m.text)


def test_unchanged_parts_are_sent_again_once_per_refresh(ros_context):
    """An untouched body part's markers and image come once per view.refresh_s, not every display period."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import Image
    from visualization_msgs.msg import MarkerArray

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.nodes.contact_node import ContactNode

    node = ContactNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="nao"), Parameter("body_parts", value=["chest"]),
        Parameter("qos.frames.reliability", value="reliable"), Parameter("view.rate_hz", value=20.0),
        Parameter("view.refresh_s", value=0.5), Parameter("view.stale_s", value=30.0)])
    io = rclpy.create_node("contact_test_refresh", context=ros_context)
    arrays, images = [], []
    io.create_subscription(MarkerArray, "tactile/chest/markers", arrays.append, _rviz_qos())
    io.create_subscription(Image, "tactile/chest/image", images.append, _rviz_qos())
    pub = io.create_publisher(SkinPartFrames, "tactile/chest/frames", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(io)
    try:
        assert node.refresh_ticks == 10
        assert _feed_until(ex, pub, lambda: node.display_ticks >= 40 and len(arrays) >= 4)
        refreshes = -(-node.display_ticks // 10)  # ticks 0, 10, 20, ... send everything
        sizes = [len(a.markers) for a in arrays]
        # the same forces in every message: besides the refreshes (every marker), one array when the first
        # frames arrive (the cells' colours and the contact), and nothing else
        assert sizes.count(32 + 3) <= refreshes and len(sizes) - sizes.count(32 + 3) <= 1, sizes
        assert len(images) <= refreshes + 1
        assert node.markers_published >= sum(sizes)
    finally:
        ex.shutdown()
        node.destroy_node()
        io.destroy_node()


def test_a_flood_of_frames_does_not_hold_off_the_display(ros_context):
    """The frames callback closes a display period when one is due: no executor spins the timer here."""
    node = _chest_node(ros_context, view__rate_hz=20.0)
    try:
        t, seq, deadline = 5_000_000_000, 0, time.monotonic() + 30.0
        while node.display_ticks < 3 and time.monotonic() < deadline:
            node._on_frames(_chest_frames(t, seq))  # as the executor would call it, back to back
            t, seq = t + 10_000_000, seq + 1
        # nobody subscribes to the chest's contact or wrench: each message's contact is counted, not published
        assert node.display_ticks >= 3 and node.contacts_unsubscribed == seq and node.contacts_published == 0
        # a period apart at most ~20 Hz: ticks come from due periods, not from every message
        assert node.display_ticks <= 1 + (time.monotonic() - (deadline - 30.0)) / (0.9 / 20.0)
    finally:
        node.destroy_node()


@pytest.mark.parametrize("lazy", [True, False])
def test_a_contact_is_worked_out_for_its_subscribers(ros_context, lazy):
    """``contact.lazy``: with no subscriber to a body part's contact or wrench, a frames message's contact is
    counted (``contacts_unsubscribed``) and neither built nor published; from the moment one subscribes to either,
    every message's is.  ``contact.lazy`` false publishes every message's, subscribed or not."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import SingleThreadedExecutor

    node = _chest_node(ros_context, view__rate_hz=0.0, contact__lazy=lazy)
    io = rclpy.create_node("contact_lazy_io", context=ros_context)
    try:
        t, seq = _feed(node, 5, 5_000_000_000, 0)
        assert (node.contacts_published, node.contacts_unsubscribed) == ((0, 5) if lazy else (5, 0))
        assert node._status().values["contacts_unsubscribed"] == node.contacts_unsubscribed
        io.create_subscription(WrenchStamped, "tactile/chest/wrench", lambda _msg: None, 10)
        pub = node.parts["chest"].pubs["wrench"]
        ex = SingleThreadedExecutor(context=ros_context)
        ex.add_node(io)
        try:
            assert spin_until(ex, lambda: pub.get_subscription_count() >= 1, timeout_s=30.0)
        finally:
            ex.shutdown()
        _feed(node, 5, t, seq)
        assert (node.contacts_published, node.contacts_unsubscribed) == ((5, 5) if lazy else (10, 0))
        assert node.parts["chest"].messages == node.contacts_published
    finally:
        node.destroy_node()
        io.destroy_node()


def test_contact_lazy_is_set_while_the_node_runs(ros_context):
    from rclpy.parameter import Parameter

    node = _chest_node(ros_context, view__rate_hz=0.0)
    try:
        assert node.lazy is True
        assert node.set_parameters([Parameter("contact.lazy", value=False)])[0].successful
        _feed(node, 1, 5_000_000_000, 0)
        assert (node.lazy, node.contacts_published, node.contacts_unsubscribed) == (False, 1, 0)
    finally:
        node.destroy_node()


def test_frames_read_from_their_bytes_give_the_contacts_rclpys_messages_give(ros_context):
    """The same chest messages, handed to one node as the bytes a serialised subscription takes and to another as
    rclpy's messages, give the same contacts and wrenches, field for field."""
    from rclpy.serialization import serialize_message

    from tactile_descriptors_ros.codecs import cdr

    if not cdr.available():
        pytest.skip("no compiled backend: the bytes are read by rclpy")
    nodes = [_chest_node(ros_context, view__rate_hz=0.0, contact__lazy=False) for _ in range(2)]
    got: list[list] = [[], []]
    try:
        for node, out in zip(nodes, got):
            for kind in ("contact", "wrench"):
                node.parts["chest"].pubs[kind].publish = out.append
        for k in range(6):
            msg = _chest_frames(5_000_000_000 + k * 10_000_000, k)
            nodes[0]._on_frames(serialize_message(msg))
            nodes[1]._on_frames(msg)
        assert len(got[0]) == len(got[1]) == 12 and not +nodes[0].faults and not +nodes[1].faults
        assert got[0][0].in_contact and got[0][0].force_n == pytest.approx(1.5, abs=0.01)
        for a, b in zip(*got):
            assert a == b  # rclpy messages compare field by field
    finally:
        for node in nodes:
            node.destroy_node()
