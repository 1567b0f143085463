"""classifier_node's label path through DDS: a burst of 1,000 labels, expiry, refusals, durable saves."""

from __future__ import annotations

import numpy as np
import pytest
from descriptor_msgs import descriptor_msg
from helpers import spin_until

pytestmark = pytest.mark.ros


@pytest.fixture
def classifier(ros_context, tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    model = tmp_path / "model.json"
    c = ClassifierNode(context=ros_context, parameter_overrides=[
        Parameter("model_path", value=str(model)), Parameter("label_horizon", value=1000),
        Parameter("label_expiry_explorations", value=5), Parameter("max_class_name_chars", value=16)])
    io = rclpy.create_node("label_io", context=ros_context)
    preds: list = []
    keep_all = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    io.create_subscription(Prediction, "tactile/prediction", preds.append, keep_all)
    desc = io.create_publisher(Descriptor, "tactile/descriptor", keep_all)
    labels = io.create_publisher(Label, "tactile/label", keep_all)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(c)
    ex.add_node(io)
    assert spin_until(ex, lambda: desc.get_subscription_count() >= 1 and labels.get_subscription_count() >= 1, 10)
    yield {"ex": ex, "node": c, "desc": desc, "labels": labels, "preds": preds, "model": model, "Label": Label}
    c.close()


def _describe(g, eids, rng) -> None:
    """Publish descriptors in groups below the node's descriptor depth, waiting for each group's predictions."""
    eids = list(eids)
    for k in range(0, len(eids), 25):
        n = len(g["preds"])
        for eid in eids[k:k + 25]:
            g["desc"].publish(descriptor_msg(eid, rng))
        want = n + len(eids[k:k + 25])
        assert spin_until(g["ex"], lambda: len(g["preds"]) >= want, 60), f"{len(g['preds'])} of {want} predictions"


def test_a_burst_of_1000_labels_is_learned_completely_and_durably(classifier):
    from tactile_descriptors_ros.core.learning import OnlineClassifier

    g = classifier
    rng = np.random.default_rng(0)
    _describe(g, range(1, 1001), rng)
    for eid in range(1, 1001):                       # all at once, no waiting
        g["labels"].publish(g["Label"](exploration_id=eid, class_name=f"m{eid % 10}"))
    node = g["node"]
    assert spin_until(g["ex"], lambda: node.counts["labels_received"] == 1000, 120), dict(node.counts)
    assert node.labels.counts["labels_learned"] == 1000 and node.model.pa.updates == 1000
    refused = {k: v for k, v in node.labels.counts.items() if k not in ("labels_learned", "early_labels")}
    assert refused == {}
    assert OnlineClassifier.load(g["model"]).version == 1000   # every one of them saved


def test_held_label_expires_and_bad_labels_are_counted_in_diagnostics(classifier):
    g = classifier
    node = g["node"]
    rng = np.random.default_rng(1)
    _describe(g, [1], rng)
    label = g["Label"]
    for eid, name in ((2, "cork"), (1, "cork"), (1, "felt"), (1, "x" * 17), (0, "")):
        g["labels"].publish(label(exploration_id=eid, class_name=name))
    assert spin_until(g["ex"], lambda: node.counts["labels_received"] == 5, 30)
    _describe(g, range(3, 8), rng)                   # exploration 2 never comes; 7 is five ids past it
    counts = node.labels.counts
    assert (counts["labels_learned"], counts["label_expired"], counts["conflicting_label"],
            counts["class_name_too_long"], counts["empty_label"]) == (1, 1, 1, 1, 1)
    st = next(s for s in node.diagnostics.statuses() if s.name.endswith("classifier"))
    values = {kv.key: kv.value for kv in st.values}
    assert st.level == b"\x01" and values["label_expired"] == "1" and values["pending_labels"] == "0"
    assert node.model.classes == ["cork"]


def test_kept_descriptors_share_the_models_labels(classifier):
    """The descriptors kept for late labels hold one shared tuple of labels (the model's), not a copy each:
    with the NAO's 917 labels a copy is about 80 kB, and the node grew by one per touch up to its horizon."""
    g = classifier
    node = g["node"]
    _describe(g, range(1, 6), np.random.default_rng(2))
    kept = [k.item.sample.labels for k in node.labels._kept.values()]
    assert len(kept) == 5 and all(labels is node.model.labels for labels in kept)
