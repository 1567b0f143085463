"""classifier_node under a careless or hostile domain, through DDS: the ~/label service, ~/reset off by default,
lost labels counted, refused parameters, frames of predictions, held labels logged."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from descriptor_msgs import descriptor_msg
from node_helpers import spin_until
from ros_cli import run_ros2

pytestmark = pytest.mark.ros


@pytest.fixture
def wired(ros_context, tmp_path):
    """A classifier (model file in tmp_path) and a node ``io`` beside it: descriptor and label publishers, the
    predictions and /rosout lines it receives, clients of ~/label and ~/reset; matched before the test starts."""
    import rclpy
    from rcl_interfaces.msg import Log
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Trigger

    from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction
    from tactile_descriptors_msgs.srv import LearnLabel
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    model = tmp_path / "model.json"
    node = ClassifierNode(context=ros_context, parameter_overrides=[Parameter("model_path", value=str(model))])
    io = rclpy.create_node("hostile_io", context=ros_context)
    keep_all = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    out = {"preds": [], "log": []}
    io.create_subscription(Prediction, "tactile/prediction", out["preds"].append, keep_all)
    io.create_subscription(Log, "/rosout", lambda m: out["log"].append(m) if m.name == "classifier_node" else None,
                           keep_all)
    g = {"node": node, "model": model, "out": out, "Label": Label, "LearnLabel": LearnLabel, "Trigger": Trigger,
         "desc": io.create_publisher(Descriptor, "tactile/descriptor", keep_all),
         "labels": io.create_publisher(Label, "tactile/label", keep_all),
         "label_srv": io.create_client(LearnLabel, "/classifier_node/label"),
         "reset_srv": io.create_client(Trigger, "/classifier_node/reset"),
         "ex": SingleThreadedExecutor(context=ros_context)}
    g["ex"].add_node(node)
    g["ex"].add_node(io)
    assert spin_until(g["ex"], lambda: g["desc"].get_subscription_count() >= 1 and node.pub.get_subscription_count()
                      >= 1 and g["label_srv"].service_is_ready() and g["reset_srv"].service_is_ready(), 60)
    yield g
    node.close()
    g["ex"].shutdown(timeout_sec=0.5)
    node.destroy_node()
    io.destroy_node()


def _call(g, client, request):
    future = client.call_async(request)
    assert spin_until(g["ex"], future.done, 60), "no answer"
    return future.result()


def _describe(g, eid, rng, frame_id=""):
    n = len(g["out"]["preds"])
    msg = descriptor_msg(eid, rng)
    msg.header.frame_id = frame_id
    g["desc"].publish(msg)
    assert spin_until(g["ex"], lambda: len(g["out"]["preds"]) > n, 60)
    return g["out"]["preds"][-1]


def test_the_label_service_answers_once_the_label_is_learned_and_saved(wired):
    from tactile_descriptors_ros.core.model_store import load_model

    g = wired
    rng = np.random.default_rng(0)
    _describe(g, 1, rng)
    answer = _call(g, g["label_srv"], g["LearnLabel"].Request(exploration_id=1, class_name=" ｃｏｒｋ "))
    assert (answer.success, answer.saved, answer.outcome, answer.class_name, answer.model_version) == \
        (True, True, "learned", "cork", 1)
    assert load_model(g["model"]).version == 1  # saved means a restart loads it
    # a label for an exploration not seen yet is answered when that exploration has been learned
    future = g["label_srv"].call_async(g["LearnLabel"].Request(exploration_id=2, class_name="felt"))
    assert spin_until(g["ex"], lambda: g["node"].labels.held == 1, 60) and not future.done()
    _describe(g, 2, rng)
    assert spin_until(g["ex"], future.done, 60)
    assert (future.result().outcome, future.result().exploration_id, future.result().model_version) == \
        ("learned", 2, 2)
    # a refusal is answered with its reason
    refused = _call(g, g["label_srv"], g["LearnLabel"].Request(exploration_id=2, class_name="steel"))
    assert (refused.success, refused.outcome, refused.reason) == (False, "refused", "conflicting_label")
    assert "already learned as 'felt'" in refused.message


def test_reset_is_refused_unless_enabled(wired):
    g = wired
    _describe(g, 1, np.random.default_rng(1))
    g["labels"].publish(g["Label"](exploration_id=1, class_name="cork"))
    assert spin_until(g["ex"], lambda: g["node"].model.pa.updates == 1, 60)
    answer = _call(g, g["reset_srv"], g["Trigger"].Request())
    assert not answer.success and "enable_reset" in answer.message
    assert g["node"].model.pa.updates == 1 and g["node"].counts["reset_refused"] == 1


def test_predictions_carry_the_robots_frame(wired):
    from rclpy.parameter import Parameter

    g = wired
    rng = np.random.default_rng(2)
    assert _describe(g, 1, rng, frame_id="shadow_hand").header.frame_id == "shadow_hand"
    assert g["node"].set_parameters([Parameter("frame_id", value="palm")])[0].successful
    assert _describe(g, 2, rng, frame_id="shadow_hand").header.frame_id == "palm"
    result = g["node"].set_parameters([Parameter("frame_id", value="x" * 300)])[0]
    assert not result.successful and "256" in result.reason


def test_a_label_held_for_an_exploration_that_never_comes_is_logged_and_expires_by_time(wired):
    from rclpy.parameter import Parameter

    g = wired
    _describe(g, 1, np.random.default_rng(3))
    g["labels"].publish(g["Label"](exploration_id=5, class_name="cork"))
    assert spin_until(g["ex"], lambda: any("exploration 5 held until it arrives" in m.msg for m in g["out"]["log"]),
                      60)
    assert g["node"].set_parameters([Parameter("label_hold_s", value=0.2)])[0].successful
    assert spin_until(g["ex"], lambda: any("exploration 5 expired: held 0.2 s" in m.msg for m in g["out"]["log"]),
                      60)
    assert g["node"].labels.counts["label_expired"] == 1 and g["node"].labels.held == 0


_BURST = textwrap.dedent("""
    import sys, time
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from tactile_descriptors_msgs.msg import Label
    rclpy.init()
    node = rclpy.create_node("label_burst")
    pub = node.create_publisher(Label, "/tactile/label", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    while pub.get_subscription_count() < 1:
        time.sleep(0.01)
    print("matched", flush=True)
    sys.stdin.readline()  # until the classifier has matched this publisher too (what it gets before, it ignores)
    for i in range(int(sys.argv[1])):
        pub.publish(Label(exploration_id=0, class_name="cork"))
    print("sent", flush=True)
    sys.stdin.readline()  # stay until the test has counted (a writer's end would discard what is in flight)
""")


def test_labels_a_publisher_drops_in_a_burst_are_counted(wired):
    """1,000 labels from another process at once through a publisher history of 10 (as ``ros2 topic pub``
    keeps): every one is either received or counted lost, none vanishes."""
    g = wired
    node = g["node"]
    n = 1_000
    others = node.sub_label.get_publisher_count()
    proc = subprocess.Popen([sys.executable, "-c", _BURST, str(n)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": os.getcwd()})
    try:
        assert proc.stdout.readline() == "matched\n"
        # discovery matches the two ends one way at a time: a sample sent before the reader has matched the
        # writer is neither received nor lost for DDS (a volatile reader starts at its match)
        assert spin_until(g["ex"], lambda: node.sub_label.get_publisher_count() > others, 60), "never matched"
        proc.stdin.write("go\n")
        proc.stdin.flush()
        assert spin_until(g["ex"], lambda: node.counts["labels_received"] > 0, 60), "no label arrived"
        assert spin_until(g["ex"], lambda: node.counts["labels_received"] + node.counts["labels_lost"] == n, 240), \
            dict(node.counts)
        assert proc.stdout.readline() == "sent\n"
    finally:
        proc.stdin.close()
        proc.wait(timeout=30)
        proc.stdout.close()
    st = next(s for s in node.diagnostics.statuses() if s.name.endswith("classifier"))
    values = {kv.key: kv.value for kv in st.values}
    assert values["labels_received"] == str(node.counts["labels_received"])
    if node.counts["labels_lost"]:
        assert st.level == b"\x01" and "labels_lost=" in st.message


# ----------------------------------------------------------------- parameters
_VALUES = [0, -1, 2**62, 1e-300, 1e300, float("nan"), float("inf"), float("-inf"), "", "a string", "x" * 10_000]
_ACCEPTED = {  # what each writable parameter takes of _VALUES (an integer for a double is widened); the rest
    # is refused with a reason
    "eta": [], "label_horizon": [], "label_wait_s": [0, 1e-300], "label_hold_s": [],
    "save_after_update": [], "frame_id": [""],  # a frame id with a blank is refused, as by every node
}


def test_every_writable_classifier_parameter_refuses_bad_values_with_a_reason_and_the_node_lives(wired):
    from rclpy.parameter import Parameter

    g = wired
    node = g["node"]
    writable = {n for n in node._parameters if not node.describe_parameters([n])[0].read_only} - {"use_sim_time"}
    assert writable == set(_ACCEPTED)
    for name, accepted in _ACCEPTED.items():
        before = node.get_parameter(name).value
        for value in _VALUES:
            result = node.set_parameters([Parameter(name, value=value)])[0]
            want = any(type(v) is type(value) and v == value for v in accepted)
            assert result.successful == want, (name, value, result.reason)
            if not result.successful:
                assert result.reason, (name, value)
                assert node.get_parameter(name).value == before
            else:
                node.set_parameters([Parameter(name, value=before)])
    # alive and learning: a descriptor is predicted and a label learned
    rng = np.random.default_rng(4)
    _describe(g, 1, rng)
    assert _call(g, g["label_srv"], g["LearnLabel"].Request(exploration_id=1, class_name="cork")).success


@pytest.mark.ros2cli
@pytest.mark.slow
def test_the_values_that_stopped_the_classifier_are_refused_through_the_ros2_cli(tmp_path):
    """``ros2 param set`` as a user types it: each writable parameter given the value that stopped the node or
    that it took silently; each refused with a reason, the node alive and its value unchanged."""
    import random
    import time

    ns = f"cli_{random.randint(0, 10**9)}"
    env = {**os.environ, "ROS_DOMAIN_ID": str(random.randint(1, 100)), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONPATH": os.pathsep.join(p for p in (os.getcwd(), os.environ.get("PYTHONPATH", "")) if p)}
    log = open(tmp_path / "node.log", "w")
    node = subprocess.Popen([sys.executable, "-m", "tactile_descriptors_ros.nodes.classifier_node", "--ros-args",
                             "-r", f"__ns:=/{ns}", "-p", f"model_path:={tmp_path / 'model.json'}"],
                            stdout=log, stderr=subprocess.STDOUT, env=env)

    def ros2(*args: str, stdout_only: bool = False) -> str:
        deadline = time.monotonic() + 180
        while True:  # asked again while the CLI's own discovery has not yet seen the node
            run = run_ros2(*args, env=env, timeout_s=120)
            assert not run.stopped, f"ros2 {' '.join(args)}: no answer within 120 s:\n{run.text}"
            if not any(m in run.text for m in ("Node not found", "Wait for service timed out")):
                # stderr may carry Fast DDS's stamped transport warnings on a loaded machine
                return run.stdout if stdout_only else run.text
            assert node.poll() is None and time.monotonic() < deadline, text

    try:
        before = ros2("param", "dump", "--no-daemon", f"/{ns}/classifier_node", stdout_only=True)
        assert "label_wait_s: 2.0" in before, before
        for name, value in (("label_wait_s", ".inf"), ("label_wait_s", "1e300"), ("eta", ".inf"),
                            ("eta", "1e300"), ("label_horizon", str(2**62)), ("label_hold_s", ".nan"),
                            ("frame_id", "x" * 1000), ("save_after_update", "'a string'")):
            text = ros2("param", "set", "--no-daemon", f"/{ns}/classifier_node", name, value)
            assert "Setting parameter failed" in text and len(text.strip()) > len("Setting parameter failed"), text
            assert node.poll() is None, (tmp_path / "node.log").read_text()
        after = ros2("param", "dump", "--no-daemon", f"/{ns}/classifier_node", stdout_only=True)
        assert after == before  # nothing changed
    finally:
        if node.poll() is None:
            os.kill(node.pid, 2)
            node.wait(timeout=30)
        log.close()
    assert node.returncode == 0, (tmp_path / "node.log").read_text()


def _learn_one(ros_context, msg):
    """A classifier with the default model path learns one label on ``msg``; the model file it used."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import Descriptor, Prediction
    from tactile_descriptors_msgs.srv import LearnLabel
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    node = ClassifierNode(context=ros_context, parameter_overrides=[Parameter("robot", value="shadow_hand")])
    io = rclpy.create_node("layout_io", context=ros_context)
    preds = []
    io.create_subscription(Prediction, "tactile/prediction", preds.append, 10)
    pub = io.create_publisher(Descriptor, "tactile/descriptor", 10)
    client = io.create_client(LearnLabel, "/classifier_node/label")
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(io)
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1 and client.service_is_ready()
                          and node.pub.get_subscription_count() >= 1, 60)
        pub.publish(msg)
        assert spin_until(ex, lambda: len(preds) == 1, 60)
        future = client.call_async(LearnLabel.Request(exploration_id=1, class_name="cork"))
        assert spin_until(ex, future.done, 60) and future.result().saved
        return node.model_path
    finally:
        node.close()
        ex.shutdown(timeout_sec=0.5)
        node.destroy_node()
        io.destroy_node()


def test_each_descriptor_layout_has_its_own_default_model_and_a_mismatch_never_advises_reset(ros_context, tmp_path,
                                                                                            monkeypatch):
    """The default model path holds one file per layout: the concatenated descriptor of one window node and the
    pooled one of a window node per body part (split_window_nodes) are learned into two files; a given
    model_path of another layout is refused with advice that keeps the model."""
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.core.model_store import layout_file_name, load_model
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode, default_model_folder
    from tactile_descriptors_ros.nodes.conversions import descriptor_from_msg

    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    rng = np.random.default_rng(5)
    concat = descriptor_msg(1, rng)
    pooled = descriptor_msg(1, rng)
    pooled.labels = [lab.replace("index/", "pooled/") for lab in pooled.labels]
    files = [_learn_one(ros_context, msg) for msg in (concat, pooled)]
    folder = default_model_folder("classifier_node", "/", "shadow_hand")
    assert files == [folder / layout_file_name(tuple(concat.labels)), folder / layout_file_name(tuple(pooled.labels))]
    assert files[0] != files[1] and all(load_model(f).version == 1 for f in files)
    # a given model file of the other layout: refused, and the advice keeps the model
    node = ClassifierNode(context=ros_context, parameter_overrides=[Parameter("model_path", value=str(files[0]))])
    try:
        assert node._predict(descriptor_from_msg(pooled)) is None
        assert "another model_path" in node.layout_error and "reset" not in node.layout_error
        assert load_model(files[0]).version == 1
    finally:
        node.destroy_node()
