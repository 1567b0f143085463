"""Record and replay through real rclpy topics, in one process (one rclpy.Context per test)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tactile_descriptors_ros.bags.io import BagReader, BagWriter, bag_info
from tactile_descriptors_ros.bags.types import tactile_typestore

pytestmark = pytest.mark.ros


#: Bound of every wait on discovery or delivery: generous for a loaded machine (each wait ends at its event).
WAIT_S = 60.0


def _wait(cond, timeout_s=WAIT_S):
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            return False
        time.sleep(0.02)
    return True


class _Spinner:
    """Spin some nodes in a background thread."""

    def __init__(self, context, *nodes):
        from rclpy.executors import SingleThreadedExecutor

        self.executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            self.executor.add_node(n)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.02)

    def close(self):
        self.stop.set()
        self.thread.join()
        self.executor.shutdown(timeout_sec=0.5)


def test_cdr_round_trip_between_rclpy_and_rosbags(ros_message_examples):
    from rclpy.serialization import deserialize_message, serialize_message

    store = tactile_typestore()
    for msg in ros_message_examples:
        msgtype = f"tactile_descriptors_msgs/msg/{type(msg).__name__}"
        data = serialize_message(msg)
        decoded = store.deserialize_cdr(data, msgtype)  # rclpy -> rosbags
        ours = bytes(store.serialize_cdr(decoded, msgtype))
        assert len(ours) == len(data)  # same layout (alignment padding bytes may differ: Fast CDR leaves them)
        assert deserialize_message(ours, type(msg)) == msg  # rosbags -> rclpy
        assert bytes(store.serialize_cdr(store.deserialize_cdr(ours, msgtype), msgtype)) == ours


def test_bag_hashes_equal_live_rclpy_hashes(ros_context, tmp_path, ros_message_examples):
    """The hash written into the bag is the one rclpy announces for a live publisher of the type."""
    import rclpy

    node = rclpy.create_node("hash_probe", context=ros_context)
    path = tmp_path / "bag"
    with BagWriter(path) as bag:
        for i, msg in enumerate(ros_message_examples):
            node.create_publisher(type(msg), f"/hash_{i}", 1)
            bag.add_topic(f"/hash_{i}", f"tactile_descriptors_msgs/msg/{type(msg).__name__}")
    info = bag_info(path)
    for i in range(len(ros_message_examples)):
        live = node.get_publishers_info_by_topic(f"/hash_{i}")
        assert len(live) == 1
        assert str(live[0].topic_type_hash) == info.topics[f"/hash_{i}"].type_hash
    node.destroy_node()


def test_record_then_replay_gives_identical_bytes(ros_context, tmp_path, ros_message_examples):
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock

    from tactile_descriptors_ros.bags.live import TopicSelector
    from tactile_descriptors_ros.bags.record import record
    from tactile_descriptors_ros.bags.replay import Player, PlayOptions

    examples = ros_message_examples
    qos = {0: qos_profile_sensor_data,
           4: QoSProfile(depth=5, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)}
    pub_node = rclpy.create_node("bag_source", context=ros_context)
    pubs = [pub_node.create_publisher(type(m), f"/rec_{i}", qos.get(i, 10)) for i, m in enumerate(examples)]
    bag = tmp_path / "recorded"
    holder, stop = [], threading.Event()
    thread = threading.Thread(target=record, args=(str(bag), TopicSelector(regex=r"^/rec_\d$")),
                              kwargs=dict(context=ros_context, stop=stop, on_start=holder.append))
    thread.start()
    assert _wait(lambda: holder and len(holder[0].topics) == len(examples)), "recorder did not subscribe"
    # matched on both sides: each publisher sees the recorder and each recorder subscription its publisher
    recorder_subs = holder[0]._subscriptions
    assert _wait(lambda: all(p.get_subscription_count() >= 1 for p in pubs)
                 and all(sub.get_publisher_count() >= 1 for sub in recorder_subs.values())), "not matched"
    sent = []
    for k in range(4):   # 4 per topic: within every publisher's depth
        for i, (p, m) in enumerate(zip(pubs, examples)):
            m.header.stamp.sec = 100 + k
            p.publish(m)
            sent.append((f"/rec_{i}", serialize_message(m)))
    assert _wait(lambda: holder[0].report.message_count == len(sent))
    stop.set()
    thread.join()
    pub_node.destroy_node()

    info = bag_info(bag)
    assert info.topics["/rec_0"].offered_qos[0].reliability.name == "BEST_EFFORT"
    assert info.topics["/rec_4"].offered_qos[0].durability.name == "TRANSIENT_LOCAL"
    with BagReader(bag) as reader:
        recorded = [(m.topic, m.data) for m in reader.messages()]
    from rclpy.serialization import deserialize_message

    classes = {f"/rec_{i}": type(m) for i, m in enumerate(examples)}
    assert len(recorded) == len(sent)
    decode = [(t, deserialize_message(d, classes[t])) for t, d in recorded]
    for t, m in [(t, deserialize_message(d, classes[t])) for t, d in sent]:
        assert (t, m) in decode  # every published message, recorded unchanged

    # Replay onto live topics: same bytes, recorded QoS offered, /clock follows the bag.
    sink = rclpy.create_node("bag_sink", context=ros_context)
    got: list[tuple[str, bytes]] = []
    for i, m in enumerate(examples):
        sink.create_subscription(type(m), f"/rec_{i}", lambda d, t=f"/rec_{i}": got.append((t, bytes(d))),
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True)
    clocks: list[int] = []
    sink.create_subscription(Clock, "/clock", lambda c: clocks.append(c.clock.sec * 10**9 + c.clock.nanosec),
                             QoSProfile(depth=100))
    spinner = _Spinner(ros_context, sink)
    try:
        player = Player(str(bag), PlayOptions(rate=2.0, clock=True, wait_for_subscribers_s=WAIT_S), context=ros_context)
        offered = {i: player.node.get_publishers_info_by_topic(f"/rec_{i}") for i in (0, 4)}
        report = player.play()
        player.destroy()
        assert _wait(lambda: len(got) == len(recorded))
        # the clock before the last message may be served after it (one executor, several subscriptions)
        _wait(lambda: bool(clocks) and clocks[-1] == info.end_ns)
    finally:
        spinner.close()
        sink.destroy_node()
    # Same bytes, and per topic the bag's order.  Messages of different topics recorded in one burst
    # replay at one instant; which subscription the sink's executor serves first is not the player's to fix.
    expected = [(m.topic, m.data) for m in BagReader(bag).open().messages()]
    assert len(got) == len(expected)
    for topic in {t for t, _ in expected}:
        assert [d for t, d in got if t == topic] == [d for t, d in expected if t == topic], topic
    assert report.message_count == len(recorded) and not report.skipped
    assert offered[0][0].qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert offered[4][0].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert clocks and clocks == sorted(clocks) and clocks[-1] == info.end_ns


def test_record_command_stops_cleanly_on_sigint(ros_context, tmp_path):
    """`tactile record` in a subprocess: SIGINT closes the bag with metadata and what arrived."""
    import rclpy
    from rclpy.duration import Duration
    from std_msgs.msg import String

    node = rclpy.create_node("sigint_source", context=ros_context)
    pub = node.create_publisher(String, "/sigint_topic", 10)
    bag = tmp_path / "sig"
    env = dict(os.environ)
    proc = subprocess.Popen([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "record", "/sigint_topic",
                             "-o", str(bag)], stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stderr.readline()  # printed once the signal handlers are in place
        assert "recording to" in line, line + proc.stderr.read()
        assert _wait(lambda: pub.get_subscription_count() > 0), "the recorder's subscription was not discovered"
        for k in range(5):
            pub.publish(String(data=f"m{k}"))
        # reliable: acknowledged means the recorder's reader holds all five; Ctrl-C then writes what it holds
        assert pub.wait_for_all_acked(Duration(seconds=WAIT_S)), "the recorder did not acknowledge the messages"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        node.destroy_node()
    assert proc.returncode == 0, err
    info = bag_info(bag)
    assert info.topics["/sigint_topic"].message_count == 5
    assert Path(bag, "metadata.yaml").is_file() and "wrote" in out


def test_a_stop_writes_every_held_message_even_when_a_timer_is_ready_first(ros_context, tmp_path):
    """The recorder's stop takes what its subscriptions hold: a spin that serves its discovery timer brings no
    message, and stopping there lost the acknowledged ones (two of five under two CPU hogs)."""
    import rclpy
    from rclpy.duration import Duration
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from tactile_descriptors_ros.bags.live import TopicSelector
    from tactile_descriptors_ros.bags.record import Recorder

    node = rclpy.create_node("held_source", context=ros_context)
    pub = node.create_publisher(String, "/held_topic", 10)
    bag = tmp_path / "held"
    try:
        with BagWriter(bag) as writer:
            # a discovery timer due at every wait: it is ready whenever the executor looks
            recorder = Recorder(writer, TopicSelector(topics=["/held_topic"]), context=ros_context,
                                discovery_period_s=1e-6)
            try:
                assert _wait(lambda: recorder.discover() or recorder.topics), "the recorder did not subscribe"
                assert _wait(lambda: pub.get_subscription_count() > 0), "the recorder was not discovered"
                for k in range(5):
                    pub.publish(String(data=f"m{k}"))
                assert pub.wait_for_all_acked(Duration(seconds=WAIT_S)), "the recorder did not acknowledge"
                stop = threading.Event()
                stop.set()  # stopped before any spin: everything acknowledged is held by the subscription
                report = recorder.spin(stop=stop)
            finally:
                recorder.destroy()
    finally:
        node.destroy_node()
    assert report.messages["/held_topic"] == 5, report
    with BagReader(bag) as reader:
        assert [bytes(m.data) for m in reader.messages()] == [serialize_message(String(data=f"m{k}"))
                                                               for k in range(5)]
