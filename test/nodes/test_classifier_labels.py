"""classifier_node's label path through DDS: a burst of 1,000 labels, expiry, refusals, durable saves."""

from __future__ import annotations

import numpy as np
import pytest
from descriptor_msgs import descriptor_msg
from node_helpers import spin_until

pytestmark = pytest.mark.ros


def _wired(ros_context, classifier, namespace: str = ""):
    """A node ``label_io`` beside ``classifier`` (keep-all, reliable): publishers of descriptors and labels, the
    predictions it receives, and an executor spinning both (the caller waits for the matching)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction

    io = rclpy.create_node("label_io", namespace=namespace or None, context=ros_context)
    preds: list = []
    keep_all = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    io.create_subscription(Prediction, "tactile/prediction", preds.append, keep_all)
    desc = io.create_publisher(Descriptor, "tactile/descriptor", keep_all)
    labels = io.create_publisher(Label, "tactile/label", keep_all)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(classifier)
    ex.add_node(io)
    return io, ex, desc, labels, preds


@pytest.fixture
def classifier(ros_context, tmp_path):
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import Label
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    model = tmp_path / "model.json"
    c = ClassifierNode(context=ros_context, parameter_overrides=[
        Parameter("model_path", value=str(model)), Parameter("label_horizon", value=1000),
        Parameter("label_expiry_explorations", value=5), Parameter("max_class_name_chars", value=16)])
    io, ex, desc, labels, preds = _wired(ros_context, c)
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
        assert spin_until(g["ex"], lambda want=want: len(g["preds"]) >= want, 60), \
            f"{len(g['preds'])} of {want} predictions"


def test_a_burst_of_1000_labels_is_learned_completely_and_durably(classifier):
    from tactile_descriptors_ros.core.model_store import load_model

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
    assert load_model(g["model"]).version == 1000   # every one of them saved


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


def _stamp_order_run(ros_context, tmp_path, run: str, descriptor_first: bool, wait_s: float):
    """Exploration 1, its label (id 0, stamped half a second after it ended) and exploration 2, with the
    label reaching the node before or after exploration 2's descriptor; return exploration 2's prediction."""
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import Label
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    c = ClassifierNode(context=ros_context, namespace=f"/{run}", parameter_overrides=[
        Parameter("model_path", value=str(tmp_path / f"{run}.json")), Parameter("label_wait_s", value=wait_s),
        Parameter("prediction_order", value="stamp")])
    io, ex, desc, labels, preds = _wired(ros_context, c, namespace=f"/{run}")
    try:
        assert spin_until(ex, lambda: desc.get_subscription_count() >= 1 and labels.get_subscription_count() >= 1
                          and c.pub.get_subscription_count() >= 1, 60), "not matched"
        rng = np.random.default_rng(3)
        d1, d2 = descriptor_msg(1, rng), descriptor_msg(2, rng)
        label = Label(exploration_id=0, class_name="cork")
        label.header.stamp.sec, label.header.stamp.nanosec = 12, 500_000_000  # after 1 ended (12 s), before 2 (22 s)
        desc.publish(d1)
        assert spin_until(ex, lambda: len(preds) == 1, 60)
        if descriptor_first:
            desc.publish(d2)
            assert spin_until(ex, lambda: c.counts["descriptors"] == 2, 60)
            labels.publish(label)
        else:
            labels.publish(label)
            assert spin_until(ex, lambda: c.counts["labels_received"] == 1, 60)
            desc.publish(d2)
        assert spin_until(ex, lambda: len(preds) == 2 and c.counts["labels_received"] == 1, 60), dict(c.counts)
        return preds[1], c.order.counts.copy()
    finally:
        c.close()
        ex.shutdown(timeout_sec=0.5)
        c.destroy_node()
        io.destroy_node()


def test_the_label_of_the_previous_exploration_counts_whether_it_comes_before_or_after_the_next_descriptor(
        ros_context, tmp_path):
    """Stamp order: exploration 2 is predicted with exploration 1's label (stamped before 2 ended) whichever
    of the two the node receives first; in arrival order (label_wait_s 0) the descriptor first misses it."""
    label_first, _ = _stamp_order_run(ros_context, tmp_path, "label_first", False, 30.0)
    descriptor_first, counts = _stamp_order_run(ros_context, tmp_path, "descriptor_first", True, 30.0)
    assert (label_first.has_model, label_first.updates, list(label_first.class_names)) == (True, 1, ["cork"])
    assert (descriptor_first.has_model, descriptor_first.updates, list(descriptor_first.scores)) == \
        (True, 1, list(label_first.scores))
    assert counts["descriptor_wait_expired"] == 0  # the descriptor waited for the label, not for the bound
    arrival, _ = _stamp_order_run(ros_context, tmp_path, "arrival_order", True, 0.0)
    assert (arrival.has_model, arrival.updates) == (False, 0)
