"""``classifier_node``: online material recognition (PA-I, Kaboli et al. 2018, eq. 30-32).

* Every ``Descriptor`` with contact is predicted and a ``Prediction`` is
  published (``has_model`` false until the first label was learned).
* A ``Label`` names an exploration id (0 = the most recent descriptor) and a
  class name; the kept descriptor of that exploration is learned (predict
  first, then update).  A new class name adds a class at run time.
* Which descriptor a label teaches, and when, is
  :class:`~tactile_descriptors_ros.core.labels.LabelProtocol`: late labels
  match the last ``label_horizon`` kept descriptors; a label that arrives
  *before* its descriptor is held and learned right after that descriptor's
  prediction, and expires (counted, warned) once a descriptor
  ``label_expiry_explorations`` ids past it arrived; the first label of an
  exploration wins (a second one is refused, counted, warned); class names
  longer than ``max_class_name_chars`` are refused.  Every label is learned,
  held, or counted in ``/diagnostics``.
* Descriptors and labels are taken in the order of their stamps (window end,
  label header stamp), not of their arrival
  (:class:`~tactile_descriptors_ros.core.labels.StampOrder`): a descriptor is
  predicted with the model that learned every label stamped before its window
  end, and a stamped label with id 0 names the last exploration that ended
  before it; each waits at most ``label_wait_s`` for what may still come before
  it.  A replay thus gives the same predictions however the executor orders a
  label and a descriptor that are ready together.
* Every update is made durable before it is reported ("learned exploration
  N"): one entry appended and synced to ``<model_path>.journal``
  (:class:`~tactile_descriptors_ros.core.model_store.ModelStore`), compacted into
  ``model_path`` as it grows and at shutdown.  ``model_path`` defaults to
  ``$ROS_HOME/tactile_descriptors_ros/<robot>/<node name>.json`` with the
  ``robot`` parameter, ``$ROS_HOME/tactile_descriptors_ros/<node name>.json``
  without (``ROS_HOME`` defaulting to ``~/.ros``), so two robots never share a
  model file; the parameter reads the path used.  It is reloaded at start.  A
  model trained on
  another descriptor layout is refused (an error in ``/diagnostics``; call
  ``~/reset`` or choose another path), never silently overwritten; a corrupt
  model file stops the node with an error naming the file and the key.
* Services ``~/save`` and ``~/reset`` (``std_srvs/Trigger``).

The running accuracy of predictions made *before* their label arrived (the
online learning curve) is reported in diagnostics as ``online_accuracy``.
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from rclpy.node import Node

from ..core.groups import groups_in_labels, selection_name
from ..core.labels import (DEFAULT_LABEL_WAIT_S, DEFAULT_MAX_CLASS_NAME_CHARS, EXPIRED, LEARN, REFUSED,
                           LabelProtocol, StampOrder)
from ..core.learning import PA_UPDATES, RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE, OnlineClassifier
from ..core.model_store import ModelStore
from ..core.robot import load_robot
from ..errors import ModelError, SignalError
from ..topics import DESCRIPTOR_TOPIC, LABEL_TOPIC, PREDICTION_TOPIC
from .common import Diagnostics, Status, declare, report_unknown_overrides, run_node
from .conversions import DescriptorSample, descriptor_from_msg, prediction_to_msg, stamp_to_ns
from .qos import QosDefaults, declare_qos

__all__ = ["ClassifierNode", "default_model_path", "main", "layout_mismatch"]


def default_model_path(node_name: str, robot: str = "") -> Path:
    """``$ROS_HOME/tactile_descriptors_ros/[<robot>/]<node_name>.json`` (``ROS_HOME`` defaults to ``~/.ros``).

    Each robot has its own folder, so a NAO and a Shadow Hand (both with a
    ``classifier_node``) never read or reset each other's model.
    """
    home = Path(os.environ.get("ROS_HOME") or Path.home() / ".ros")
    folder = home / "tactile_descriptors_ros"
    return (folder / robot if robot else folder) / f"{node_name}.json"


@dataclass(frozen=True)
class _Predicted:
    """A descriptor the protocol keeps for its label, with the class predicted before the label came."""

    sample: DescriptorSample
    prediction: str | None


def layout_mismatch(sample: DescriptorSample, model_labels: Sequence[str]) -> str:
    """Why a model refuses a descriptor: both feature-group selections, value counts and body parts."""
    return (f"descriptor of feature groups {selection_name(groups_in_labels(sample.labels))} "
            f"({len(sample.labels)} values, {sample.robot} {'/'.join(sample.body_parts)}) does not fit the model, "
            f"trained on feature groups {selection_name(groups_in_labels(model_labels))} ({len(model_labels)} "
            "values); call ~/reset or set another model_path")


class ClassifierNode(Node):
    """The classifier node; ``kwargs`` go to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``)."""

    def __init__(self, node_name: str = "classifier_node", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        from std_srvs.srv import Trigger
        from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction

        robot_arg = declare(self, "robot", "", "robot name or YAML path: the default model file is per robot "
                            "('' = no robot folder)")
        self.robot_name = load_robot(robot_arg).name if robot_arg else ""
        fallback = default_model_path(self.get_name(), self.robot_name)
        path = declare(self, "model_path", "",
                       "model file (JSON); '' = $ROS_HOME/tactile_descriptors_ros/<robot>/<node>.json; reads the "
                       "path used", resolve=lambda p: str(Path(os.path.expanduser(p)) if p else fallback))
        self.model_path = Path(path)
        self.eta = declare(self, "eta", 1.0, "PA-I aggressiveness (eq. 32; the paper uses 1); from the next update on",
                           minimum=1e-12, on_set=self._set_eta)
        self.log_activity = declare(self, "log_activity", True, "use log(Activity) features")
        self.standardize = declare(self, "standardize", True, "running standardisation of features")
        self.pa_update = declare(self, "pa_update", RECOMMENDED_PA_UPDATE,
                                 "PA-I update: max_loss, or prediction (the paper's eq. 30-32)", choices=PA_UPDATES)
        self.pa_average = declare(self, "pa_average", RECOMMENDED_PA_AVERAGE,
                                  "predict with the running mean of the PA weights (false: the paper's PA-I)")
        self.horizon = declare(self, "label_horizon", 100,
                               "descriptors kept for late labels (and early labels held)", minimum=1,
                               on_set=self._set_horizon)
        expiry = declare(self, "label_expiry_explorations", 10,
                         "a held label expires when a descriptor this many ids past it arrives", minimum=1)
        max_name = declare(self, "max_class_name_chars", DEFAULT_MAX_CLASS_NAME_CHARS,
                           "longest class name accepted [characters]", minimum=1)
        self.labels = LabelProtocol(self.horizon, expiry, max_name)
        self.order: StampOrder[DescriptorSample, _Predicted] = StampOrder(
            self.labels, self._predict, self._apply,
            declare(self, "label_wait_s", DEFAULT_LABEL_WAIT_S,
                    "longest wait of a descriptor for the label due before it, and of a stamped label for its "
                    "descriptor [s] (0: arrival order)", minimum=0.0, on_set=self._set_label_wait))
        self.save_after_update = declare(self, "save_after_update", True, "save the model after every update",
                                         on_set=lambda v: lambda: setattr(self, "save_after_update", v))
        self.load_on_start = declare(self, "load_model", True, "load model_path at start if it exists")
        self.frame_id = declare(self, "frame_id", "", "header.frame_id of the predictions",
                                on_set=lambda v: lambda: setattr(self, "frame_id", v))

        self.model: OnlineClassifier | None = None
        self.store = ModelStore(self.model_path, holder=self.get_fully_qualified_name())
        self.layout_error: str | None = None
        # ModelError: another node holds the file, or it is corrupt -> refuse to start
        self.model = self.store.open(load=self.load_on_start)
        if self.model is not None:
            self.get_logger().info(f"loaded model {self.model_path}: {len(self.model.classes)} classes "
                                   f"({', '.join(self.model.classes)}), {self.model.pa.updates} updates")
        self.latest: DescriptorSample | None = None
        self.counts: Counter[str] = Counter()
        self.correct_before_label = 0
        self.scored_labels = 0
        self.last_save_error: str | None = None

        qos_desc = declare_qos(self, "descriptor", QosDefaults("reliable", "volatile", 50))
        # A burst of labels must not overflow the history: each lost label is a lost update (docs/nodes.md).
        qos_label = declare_qos(self, "label", QosDefaults("reliable", "volatile", 1000))
        qos_pred = declare_qos(self, "prediction", QosDefaults("reliable", "volatile", 50))
        self.pub = self.create_publisher(Prediction, PREDICTION_TOPIC, qos_pred)
        self.sub_desc = self.create_subscription(Descriptor, DESCRIPTOR_TOPIC, self._on_descriptor, qos_desc)
        self.sub_label = self.create_subscription(Label, LABEL_TOPIC, self._on_label, qos_label)
        self.srv_save = self.create_service(Trigger, "~/save", self._srv_save)
        self.srv_reset = self.create_service(Trigger, "~/reset", self._srv_reset)
        self.diagnostics = Diagnostics(self, declare(self, "diagnostics_period_s", 1.0, "diagnostics period [s]",
                                                     minimum=0.01))
        self.diagnostics.add("classifier", self._status)
        # what waits in stamp order is released when its wait runs out, even if nothing else arrives
        self.order_timer = self.create_timer(0.05, lambda: self.order.poll(time.monotonic()))
        report_unknown_overrides(self)
        self.get_logger().info(f"model file {self.model_path}; predictions on {self.pub.topic_name}")

    # ------------------------------------------------------------- parameters
    def _set_eta(self, value: float):
        """``ros2 param set ... eta``: the model learns with the new aggressiveness from its next update."""
        def apply() -> None:
            self.eta = value
            if self.model is not None:
                self.model.pa.eta = value

        return apply

    def _set_horizon(self, value: int):
        """``ros2 param set ... label_horizon``: a smaller horizon forgets the oldest kept descriptors now."""
        def apply() -> None:
            self.horizon = value
            dropped = self.labels.set_horizon(value)
            if dropped:
                self.get_logger().warning(f"label_horizon {value}: dropped the {dropped} oldest held labels")

        return apply

    def _set_label_wait(self, value: float):
        """``ros2 param set ... label_wait_s``: from the next message (or poll) on."""
        return lambda: self.order.set_wait(value)

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
        if not np.all(np.isfinite(sample.values)):
            self.counts["nonfinite_descriptor"] += 1
            self.get_logger().warning("descriptor with non-finite values ignored", throttle_duration_sec=5.0)
            return
        self.order.add_descriptor(sample.exploration_id, sample.window_end_ns, sample, time.monotonic())

    def _predict(self, sample: DescriptorSample) -> _Predicted | None:
        """Predict one descriptor in its turn (:class:`StampOrder`); None when its layout does not fit the model."""
        if self.model is None:
            self.model = self._new_model(sample.labels)
        if sample.labels != self.model.labels:
            self.counts["layout_mismatch"] += 1
            self.layout_error = layout_mismatch(sample, self.model.labels)
            self.get_logger().error(self.layout_error, throttle_duration_sec=5.0)
            return None
        self.layout_error = None
        # the kept descriptors (label_horizon of them) share the model's labels: one copy, not one per
        # descriptor (a NAO descriptor's 917 label strings are about 80 kB; the node grew by that per touch)
        sample = replace(sample, labels=self.model.labels)
        self.model.observe(sample.values)
        name, scores = self.model.predict(sample.values)
        self.pub.publish(prediction_to_msg(sample, class_name=name, class_names=self.model.classes, scores=scores,
                                           model_version=self.model.version, updates=self.model.pa.updates,
                                           frame_id=self.frame_id))
        self.counts["predictions"] += 1
        self.latest = sample
        return _Predicted(sample, name)

    # ----------------------------------------------------------------- labels
    def _on_label(self, msg) -> None:
        self.counts["labels_received"] += 1
        self.order.add_label(int(msg.exploration_id), str(msg.class_name), stamp_to_ns(msg.header.stamp),
                             time.monotonic())

    def _apply(self, decision) -> None:
        """Carry out a :class:`~..core.labels.LabelDecision`: learn, or warn about a refusal or expiry."""
        if decision.action == LEARN:
            self._learn(decision.item, decision.class_name)
        elif decision.action in (REFUSED, EXPIRED):
            self.get_logger().warning(decision.message, throttle_duration_sec=1.0)

    def _learn(self, kept: _Predicted, name: str) -> None:
        sample = kept.sample
        if self.model is None or sample.labels != self.model.labels:  # the model was reset to another layout meanwhile
            self.counts["layout_mismatch"] += 1
            return
        self.scored_labels += 1
        self.correct_before_label += int(kept.prediction == name)
        new_class = name not in self.model.classes
        loss = self.model.learn(sample.values, name)
        self.counts["updates"] += 1
        saved = self._record() if self.save_after_update else None
        if saved is False:
            return  # _record logged the error: the update is in memory only, never reported as saved
        self.get_logger().info(f"learned exploration {sample.exploration_id}: {name!r}"
                               f"{' (new class)' if new_class else ''}, loss {loss:.3f}, "
                               f"{len(self.model.classes)} classes{', saved' if saved else ''}")

    def _record(self) -> bool:
        """Make the last update durable (journal entry, synced); False and an error when it failed."""
        try:
            self.store.record(self.model)
        except ModelError as exc:
            self.counts["save_failed"] += 1
            self.last_save_error = str(exc)
            self.get_logger().error(f"update learned in memory but not saved: {exc}")
            return False
        self.last_save_error = None
        return True

    # --------------------------------------------------------------- services
    def _save(self) -> bool:
        if self.model is None:
            return False
        try:
            self.store.save(self.model)
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
        self.labels.reset()
        self.order.reset()
        self.latest = None
        self.correct_before_label = self.scored_labels = 0
        try:
            if labels is not None:
                self.model = self._new_model(labels)
                self.store.save(self.model)
            else:
                self.store.reset()
        except ModelError as exc:
            response.success, response.message = False, f"model reset in memory, but {exc}"
            return response
        self.counts["resets"] += 1
        response.success, response.message = True, f"model reset ({self.model_path})"
        self.get_logger().info(response.message)
        return response

    def close(self) -> None:
        """At shutdown: compact the journal into the model file (a clean stop leaves one file)."""
        if self.model is not None and self.save_after_update and self.store.journal.exists():
            self._save()
        self.store.close()

    def destroy_node(self) -> None:
        """Release the model's lock (without compacting: :meth:`close` does that) and destroy the node."""
        self.store.close()
        super().destroy_node()

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
                  "kept_descriptors": self.labels.kept, "pending_labels": self.labels.held,
                  "waiting_in_stamp_order": self.order.waiting}
        values.update({k: v for k, v in sorted((self.counts + self.labels.counts + self.order.counts).items())})
        if self.layout_error:
            return Status("error", self.layout_error, values)
        if self.last_save_error:
            return Status("error", self.last_save_error, values)
        refused = {k: v for k, v in sorted(self.labels.counts.items()) if v and k not in ("labels_learned",
                                                                                          "early_labels")}
        if refused or self.counts["malformed_descriptor"]:
            what = ", ".join(f"{k}={v}" for k, v in refused.items())
            return Status("warn", f"labels not learned: {what or 'none'}; "
                                  f"{self.counts['malformed_descriptor']} malformed descriptors", values)
        return Status("ok", f"{values['classes']} classes, {values['updates']} updates", values)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``classifier_node`` executable."""
    return run_node(ClassifierNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
