"""``classifier_node``: online material recognition (PA-I, Kaboli et al. 2018, eq. 30-32).

* Every ``Descriptor`` with contact is predicted and a ``Prediction`` is
  published (``has_model`` false until the first label was learned).
* A ``Label`` names an exploration id (0 = the most recent descriptor) and a
  class name; the kept descriptor of that exploration is learned (predict
  first, then update).  A new class name adds a class at run time.
* Late labels are matched among the last ``label_horizon`` kept descriptors;
  a label that arrives *before* its descriptor is held (at most
  ``label_horizon`` of them) and applied right after that descriptor's
  prediction, so the prediction stays honest.  A label for an exploration
  that is unknown (never described, or older than the horizon) is counted
  and reported (``/diagnostics`` and a log warning), never applied to another
  descriptor.
* The model is saved atomically after every update (``model_path``; default
  ``$ROS_HOME/tactile_descriptors_ros/<node name>.json``, ``ROS_HOME``
  defaulting to ``~/.ros``) and reloaded at start.  A model trained on
  another descriptor layout is refused (an error in ``/diagnostics``; call
  ``~/reset`` or choose another path), never silently overwritten.
* Services ``~/save`` and ``~/reset`` (``std_srvs/Trigger``).

The running accuracy of predictions made *before* their label arrived (the
online learning curve) is reported in diagnostics as ``online_accuracy``.
"""

from __future__ import annotations

import os
from collections import Counter, OrderedDict
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rclpy.node import Node

from ..core.learning import PA_UPDATES, RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE, OnlineClassifier
from ..errors import ModelError, SignalError
from .common import Diagnostics, Status, declare, run_node
from .conversions import DescriptorSample, descriptor_from_msg, prediction_to_msg
from .qos import QosDefaults, declare_qos

__all__ = ["ClassifierNode", "default_model_path", "DESCRIPTOR_TOPIC", "LABEL_TOPIC", "PREDICTION_TOPIC", "main"]

DESCRIPTOR_TOPIC = "tactile/descriptor"
LABEL_TOPIC = "tactile/label"
PREDICTION_TOPIC = "tactile/prediction"


def default_model_path(node_name: str) -> Path:
    """``$ROS_HOME/tactile_descriptors_ros/<node_name>.json`` (``ROS_HOME`` defaults to ``~/.ros``)."""
    home = Path(os.environ.get("ROS_HOME") or Path.home() / ".ros")
    return home / "tactile_descriptors_ros" / f"{node_name}.json"


class ClassifierNode(Node):
    """The classifier node; ``kwargs`` go to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``)."""

    def __init__(self, node_name: str = "classifier_node", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        from std_srvs.srv import Trigger
        from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction

        path = declare(self, "model_path", "", "model file (JSON); '' = $ROS_HOME/tactile_descriptors_ros/<node>.json")
        self.model_path = Path(os.path.expanduser(path)) if path else default_model_path(self.get_name())
        self.eta = declare(self, "eta", 1.0, "PA-I aggressiveness (eq. 32; the paper uses 1)", minimum=1e-12)
        self.log_activity = declare(self, "log_activity", True, "use log(Activity) features")
        self.standardize = declare(self, "standardize", True, "running standardisation of features")
        self.pa_update = declare(self, "pa_update", RECOMMENDED_PA_UPDATE,
                                 "PA-I update: max_loss, or prediction (the paper's eq. 30-32)", choices=PA_UPDATES)
        self.pa_average = declare(self, "pa_average", RECOMMENDED_PA_AVERAGE,
                                  "predict with the running mean of the PA weights (false: the paper's PA-I)")
        self.horizon = declare(self, "label_horizon", 100,
                               "descriptors kept for late labels (and early labels held)", minimum=1)
        self.save_after_update = declare(self, "save_after_update", True, "save the model after every update")
        self.load_on_start = declare(self, "load_model", True, "load model_path at start if it exists")
        self.frame_id = declare(self, "frame_id", "", "header.frame_id of the predictions")

        self.model: OnlineClassifier | None = None
        self.layout_error: str | None = None
        if self.load_on_start and self.model_path.is_file():
            self.model = OnlineClassifier.load(self.model_path)  # ModelError: corrupt file -> refuse to start
            self.get_logger().info(f"loaded model {self.model_path}: {len(self.model.classes)} classes "
                                   f"({', '.join(self.model.classes)}), {self.model.pa.updates} updates")
        self.kept: OrderedDict[int, DescriptorSample] = OrderedDict()
        self.latest: DescriptorSample | None = None
        self.latest_id_seen = 0
        self.pending: OrderedDict[int, str] = OrderedDict()
        self.predicted: dict[int, str | None] = {}
        self.counts: Counter[str] = Counter()
        self.correct_before_label = 0
        self.scored_labels = 0
        self.last_save_error: str | None = None

        qos_desc = declare_qos(self, "descriptor", QosDefaults("reliable", "volatile", 50))
        qos_label = declare_qos(self, "label", QosDefaults("reliable", "volatile", 50))
        qos_pred = declare_qos(self, "prediction", QosDefaults("reliable", "volatile", 50))
        self.pub = self.create_publisher(Prediction, PREDICTION_TOPIC, qos_pred)
        self.sub_desc = self.create_subscription(Descriptor, DESCRIPTOR_TOPIC, self._on_descriptor, qos_desc)
        self.sub_label = self.create_subscription(Label, LABEL_TOPIC, self._on_label, qos_label)
        self.srv_save = self.create_service(Trigger, "~/save", self._srv_save)
        self.srv_reset = self.create_service(Trigger, "~/reset", self._srv_reset)
        self.diagnostics = Diagnostics(self, declare(self, "diagnostics_period_s", 1.0, "diagnostics period [s]",
                                                     minimum=0.01))
        self.diagnostics.add("classifier", self._status)
        self.get_logger().info(f"model file {self.model_path}; predictions on {self.pub.topic_name}")

    # ------------------------------------------------------------ descriptors

    def _new_model(self, labels) -> OnlineClassifier:
        """An empty model of a descriptor layout, with this node's learning parameters."""
        return OnlineClassifier(labels, eta=self.eta, log_activity=self.log_activity, standardize=self.standardize,
                                update=self.pa_update, average=self.pa_average)

    def _on_descriptor(self, msg) -> None:
        try:
            sample = descriptor_from_msg(msg)
        except SignalError as exc:
            self.counts["malformed_descriptor"] += 1
            self.get_logger().warning(f"malformed descriptor: {exc}", throttle_duration_sec=5.0)
            return
        self.counts["descriptors"] += 1
        if not sample.contact:
            self.counts["no_contact"] += 1
            return
        if self.model is None:
            self.model = self._new_model(sample.labels)
        if sample.labels != self.model.labels:
            self.counts["layout_mismatch"] += 1
            self.layout_error = (f"descriptor layout ({len(sample.labels)} values, {sample.robot} "
                                 f"{'/'.join(sample.body_parts)}) differs from the model's ({len(self.model.labels)} "
                                 f"values); call ~/reset or set another model_path")
            self.get_logger().error(self.layout_error, throttle_duration_sec=5.0)
            return
        self.layout_error = None
        if not np.all(np.isfinite(sample.values)):
            self.counts["nonfinite_descriptor"] += 1
            self.get_logger().warning("descriptor with non-finite values ignored", throttle_duration_sec=5.0)
            return
        self.model.observe(sample.values)
        name, scores = self.model.predict(sample.values)
        self.pub.publish(prediction_to_msg(sample, class_name=name, class_names=self.model.classes, scores=scores,
                                           model_version=self.model.version, updates=self.model.pa.updates,
                                           frame_id=self.frame_id))
        self.counts["predictions"] += 1
        eid = sample.exploration_id
        self.predicted[eid] = name
        self.latest = sample
        if eid:
            self.latest_id_seen = max(self.latest_id_seen, eid)
            self.kept[eid] = sample
            self.kept.move_to_end(eid)
            while len(self.kept) > self.horizon:
                old, _ = self.kept.popitem(last=False)
                self.predicted.pop(old, None)
        if eid in self.pending:
            self._learn(sample, self.pending.pop(eid))

    # ----------------------------------------------------------------- labels
    def _on_label(self, msg) -> None:
        eid = int(msg.exploration_id)
        name = str(msg.class_name).strip()
        if not name:
            self.counts["empty_label"] += 1
            self.get_logger().warning(f"label for exploration {eid} has an empty class name; ignored")
            return
        if eid == 0:
            sample = self.latest
        else:
            sample = self.kept.get(eid)
        if sample is None:
            if eid > self.latest_id_seen and len(self.pending) < self.horizon:
                self.pending[eid] = name  # its descriptor has not arrived yet
                self.counts["early_labels"] += 1
                return
            self.counts["unknown_exploration"] += 1
            self.get_logger().warning(
                f"label {name!r} for exploration {eid or '(most recent)'}: no such descriptor with contact among "
                f"the last {self.horizon} kept; ignored")
            return
        self._learn(sample, name)

    def _learn(self, sample: DescriptorSample, name: str) -> None:
        if self.model is None or sample.labels != self.model.labels:  # reset meanwhile  # the model was reset to another layout meanwhile
            self.counts["layout_mismatch"] += 1
            return
        key = sample.exploration_id
        if key in self.predicted:  # first label of this prediction: score it
            guess = self.predicted.pop(key, None)
            self.scored_labels += 1
            self.correct_before_label += int(guess == name)
        new_class = name not in self.model.classes
        loss = self.model.learn(sample.values, name)
        self.counts["updates"] += 1
        self.get_logger().info(f"learned exploration {key}: {name!r}{' (new class)' if new_class else ''}, "
                               f"loss {loss:.3f}, {len(self.model.classes)} classes")
        if self.save_after_update:
            self._save()

    # --------------------------------------------------------------- services
    def _save(self) -> bool:
        if self.model is None:
            return False
        try:
            self.model.save(self.model_path)
        except ModelError as exc:
            self.counts["save_failed"] += 1
            self.last_save_error = str(exc)
            self.get_logger().error(str(exc))
            return False
        self.last_save_error = None
        return True

    def _srv_save(self, request, response):
        if self.model is None:
            response.success, response.message = False, "no model yet (no descriptor with contact received)"
        elif self._save():
            response.success, response.message = True, f"saved {len(self.model.classes)} classes to {self.model_path}"
        else:
            response.success, response.message = False, self.last_save_error or "save failed"
        return response

    def _srv_reset(self, request, response):
        labels = self.latest.labels if self.latest is not None else None
        self.model = None
        self.layout_error = None
        self.kept.clear()
        self.pending.clear()
        self.predicted.clear()
        self.latest = None
        self.correct_before_label = self.scored_labels = 0
        try:
            if labels is not None:
                self.model = self._new_model(labels)
                self.model.save(self.model_path)
            elif self.model_path.exists():
                self.model_path.unlink()
        except (ModelError, OSError) as exc:
            response.success, response.message = False, f"model reset in memory, but {exc}"
            return response
        self.counts["resets"] += 1
        response.success, response.message = True, f"model reset ({self.model_path})"
        self.get_logger().info(response.message)
        return response

    # ------------------------------------------------------------ diagnostics
    @property
    def online_accuracy(self) -> float:
        """Accuracy of the predictions made before their label arrived (NaN before any)."""
        return self.correct_before_label / self.scored_labels if self.scored_labels else float("nan")

    def _status(self) -> Status:
        values = {"model_path": str(self.model_path), "classes": len(self.model.classes) if self.model else 0,
                  "class_names": ", ".join(self.model.classes) if self.model else "",
                  "updates": self.model.pa.updates if self.model else 0,
                  "model_version": self.model.version if self.model else 0,
                  "labelled_predictions": self.scored_labels, "online_accuracy": self.online_accuracy,
                  "kept_descriptors": len(self.kept), "pending_labels": len(self.pending)}
        values.update({k: v for k, v in sorted(self.counts.items())})
        if self.layout_error:
            return Status("error", self.layout_error, values)
        if self.last_save_error:
            return Status("error", self.last_save_error, values)
        if self.counts["unknown_exploration"] or self.counts["malformed_descriptor"]:
            return Status("warn", f"{self.counts['unknown_exploration']} labels for unknown explorations, "
                                  f"{self.counts['malformed_descriptor']} malformed descriptors", values)
        return Status("ok", f"{values['classes']} classes, {values['updates']} updates", values)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``classifier_node`` executable."""
    return run_node(ClassifierNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
