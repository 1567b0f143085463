"""window_node and classifier_node in-process: descriptors, predictions, labels, model file, services."""

from __future__ import annotations

import json

import pytest
from node_helpers import BiotacStream, spin_until

from tactile_descriptors_ros.core.learning import OnlineClassifier
from tactile_descriptors_ros.core.model_store import load_model
from tactile_descriptors_ros.errors import ModelError

pytestmark = pytest.mark.ros


@pytest.fixture
def graph(ros_context, tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor, DescriptorLayout, Label, Prediction
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    model = tmp_path / "model.json"
    w = WindowNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="shadow_hand"), Parameter("body_parts", value=["index"]),
        Parameter("qos.frames.reliability", value="reliable")])
    c = ClassifierNode(context=ros_context, parameter_overrides=[Parameter("model_path", value=str(model)),
                                                                 Parameter("enable_reset", value=True)])
    io = rclpy.create_node("io", context=ros_context)
    out = {"pred": [], "desc": [], "layout": []}
    io.create_subscription(Prediction, "tactile/prediction", out["pred"].append, 50)
    io.create_subscription(Descriptor, "tactile/descriptor", out["desc"].append, 50)
    io.create_subscription(DescriptorLayout, "tactile/descriptor_layout", out["layout"].append,
                           QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    frames = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 50)
    labels = io.create_publisher(Label, "tactile/label", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (w, c, io):
        ex.add_node(n)
    spin_until(ex, lambda: frames.get_subscription_count() >= 1 and labels.get_subscription_count() >= 1, 10)
    yield {"ex": ex, "window": w, "classifier": c, "frames": frames, "labels": labels, "out": out, "model": model,
           "Label": Label}
    c.close()


def _explore(g, stream, freq_hz):
    n, nd = len(g["out"]["pred"]), len(g["out"]["desc"])
    for m in stream.exploration(freq_hz):
        g["frames"].publish(m)
        g["ex"].spin_once(timeout_sec=0.005)
    assert spin_until(g["ex"], lambda: len(g["out"]["pred"]) > n and len(g["out"]["desc"]) > nd, 10), \
        "no descriptor and prediction for the exploration"
    return g["out"]["pred"][-1]


def test_predict_then_learn_online(graph):
    g = graph
    stream = BiotacStream()
    first = _explore(g, stream, 40.0)
    assert first.exploration_id == 1 and not first.has_model and first.class_name == ""
    d = g["out"]["desc"][-1]
    assert d.body_parts == ["index"] and d.contact == [True] and len(d.values) == 261  # the shipped groups
    assert spin_until(g["ex"], lambda: g["out"]["layout"], 10)
    layout = g["out"]["layout"][0]
    assert d.window_mode == "exploration" and d.layout_id == layout.layout_id
    assert list(d.labels) == [] and layout.labels[0] == "index/per_channel/A_pac"
    from tactile_descriptors_ros.core.robot import load_robot

    root = load_robot("shadow_hand").geometry.root_frame  # every message names a frame of the TF tree
    assert first.header.frame_id == d.header.frame_id == root == "forearm"
    g["labels"].publish(g["Label"](exploration_id=1, class_name="cork"))
    assert spin_until(g["ex"], lambda: g["classifier"].model is not None and g["classifier"].model.pa.updates == 1)
    second = _explore(g, stream, 300.0)
    assert second.exploration_id == 2 and second.has_model and second.class_name == "cork"
    assert list(second.class_names) == ["cork"] and len(second.scores) == 1
    g["labels"].publish(g["Label"](exploration_id=0, class_name="felt"))  # 0 = the most recent
    assert spin_until(g["ex"], lambda: g["classifier"].model.classes == ["cork", "felt"])
    saved = load_model(g["model"])  # durable after the update (file and journal)
    assert saved.classes == ["cork", "felt"] and saved.pa.updates == 2
    third = _explore(g, stream, 40.0)
    assert list(third.class_names) == ["cork", "felt"] and third.model_version == 2


def test_refused_label_is_counted_and_reported(graph):
    g = graph
    _explore(g, BiotacStream(), 40.0)
    g["labels"].publish(g["Label"](exploration_id=0, class_name="cork"))
    g["labels"].publish(g["Label"](exploration_id=1, class_name="felt"))  # exploration 1 again: the first wins
    assert spin_until(g["ex"], lambda: g["classifier"].labels.counts["conflicting_label"] == 1)
    st = next(s for s in g["classifier"].diagnostics.statuses() if s.name.endswith("classifier"))
    values = {kv.key: kv.value for kv in st.values}
    assert st.level == b"\x01" and "conflicting_label=1" in st.message and values["conflicting_label"] == "1"
    assert g["classifier"].model.classes == ["cork"]  # never learned twice


def test_save_reset_and_reload(graph, ros_context):
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    g = graph
    c = g["classifier"]
    assert not c._srv_save(Trigger.Request(), Trigger.Response()).success  # no model yet
    _explore(g, BiotacStream(), 40.0)
    g["labels"].publish(g["Label"](exploration_id=0, class_name="cork"))
    assert spin_until(g["ex"], lambda: c.model.pa.updates == 1)
    assert c._srv_save(Trigger.Request(), Trigger.Response()).success
    assert load_model(g["model"]).classes == ["cork"] and not g["model"].with_name("model.json.journal").exists()
    # a second node on the same file is refused, naming the first (two writers would lose labels)
    with pytest.raises(ModelError, match=r"in use by /classifier_node \(pid "):
        ClassifierNode("classifier_reloaded", context=ros_context,
                       parameter_overrides=[Parameter("model_path", value=str(g["model"]))])
    resp = c._srv_reset(Trigger.Request(), Trigger.Response())
    assert resp.success and c.model.classes == []
    assert json.loads(g["model"].read_text())["pa"]["classes"] == []
    assert load_model(g["model"]).classes == []


def test_layout_mismatch_refused(graph, tmp_path, ros_context):
    """A model of another layout is never overwritten: predictions stop, diagnostics say why."""
    g = graph
    _explore(g, BiotacStream(), 40.0)
    c = g["classifier"]
    c.model = OnlineClassifier(["a", "b"])
    n = len(g["out"]["pred"])
    stream = BiotacStream(seed=3)
    for m in stream.exploration(40.0):
        g["frames"].publish(m)
        g["ex"].spin_once(timeout_sec=0.005)
    assert spin_until(g["ex"], lambda: c.counts["layout_mismatch"] >= 1)
    assert len(g["out"]["pred"]) == n
    assert "feature groups per_channel+bands+levels+statistics (261 values" in c.layout_error
    st = next(s for s in c.diagnostics.statuses() if s.name.endswith("classifier"))
    assert st.level == b"\x02"


def test_window_node_counts_unknown_sensor_and_lost_frames(graph):
    g = graph
    s = BiotacStream(sensor_name="biotac_ghost")
    g["frames"].publish(s.batch(0.0, 40.0))
    good = BiotacStream()
    g["frames"].publish(good.batch(0.0, 40.0))
    good.seq += 30  # 30 frames lost on the wire
    good.t_ns += 300_000_000
    g["frames"].publish(good.batch(0.0, 40.0))
    w = g["window"]
    assert spin_until(g["ex"], lambda: w.faults["unknown_sensor"] == 1 and w.faults["lost_frames"] == 30)
    st = w.diagnostics.statuses()[0]
    assert st.level == b"\x01" and "unknown_sensor=1" in st.message
