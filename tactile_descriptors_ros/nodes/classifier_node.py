"""``classifier_node``: online material recognition (PA-I, Kaboli et al. 2018, eq. 30-32).

* Every ``Descriptor`` with contact is predicted and a ``Prediction`` is
  published at once (``has_model`` false until the first label was
  learned); its ``header.frame_id`` is the descriptor's (or ``frame_id``).
* A ``Label`` on ``tactile/label``, or a call of the ``~/label`` service
  (``LearnLabel``: answered once the label is learned and saved, or refused
  with the reason), names an exploration id (0 = the most recent descriptor)
  and a class name; the kept descriptor of that exploration is learned
  (predict first, then update).  A new class name adds a class at run time.
* Which descriptor a label teaches, and when, is
  :class:`~tactile_descriptors_ros.core.labels.LabelProtocol` (late labels,
  labels held for explorations not seen yet and their expiry by id and by
  time, the first label of an exploration wins, class names NFKC-normalised
  and checked, at most ``max_classes`` classes, exploration ids far from the
  latest refused); every label is learned, held, or counted in
  ``/diagnostics``, and a held or refused one is logged.
* Labels are taken in the order of their stamps, not of their arrival
  (:class:`~tactile_descriptors_ros.core.labels.StampOrder`): a stamped label
  with id 0 names the last exploration that ended before it.  With
  ``prediction_order: immediate`` (the default) a descriptor is predicted the
  moment it arrives, with the model as it is; with ``stamp`` it waits (at most
  ``label_wait_s``) for the label due before it, so a replayed bag gives the
  same predictions bit for bit.  A jump back in the stamps (a replay started
  again, ``/clock`` going back) starts a new session, counted.
* Every update is durable before it is reported ("learned exploration N ...,
  saved"): one entry appended and synced to the model's journal
  (:class:`~tactile_descriptors_ros.core.model_store.ModelStore`), compacted
  into the model file as it grows and at shutdown; a compaction that fails
  (a full disk) keeps the journal, and is counted.  The model file is locked:
  a second node on it refuses to start, naming the first.
* ``model_path`` '' (the default) keeps one model per descriptor layout in
  ``$ROS_HOME/tactile_descriptors_ros/<robot>/<namespace>/<node name>/``
  (``ROS_HOME`` defaulting to ``~/.ros``; the file for a layout is named by
  its body parts, feature groups, value count and hash, and is opened at the
  first descriptor): two robots, two namespaces or two layouts never share a
  model.  A given ``model_path`` is loaded at start; a descriptor of another
  layout than its model's is refused (an error in ``/diagnostics``), never
  learned into it.  A corrupt model file stops the node with an error naming
  the file, the line and the key.
* Services ``~/save`` and ``~/reset`` (``std_srvs/Trigger``); ``~/reset``
  erases the model and answers only with ``enable_reset: true``.

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
from ..core.labels import EXPIRED, HELD, LEARN, REFUSED, LabelDecision, LabelProtocol, StampOrder
from ..core.learning import OnlineClassifier
from ..core.model_store import ModelLock, ModelStore, layout_file_name
from ..core.robot import load_robot
from ..errors import ModelError, SignalError
from ..params.classifier_node import CLASSIFIER_NODE
from ..topics import DESCRIPTOR_TOPIC, LABEL_TOPIC, PREDICTION_TOPIC, layout_topic
from .common import Diagnostics, Status, StopsQuietly, run_node
from .conversions import DescriptorLayouts, DescriptorSample, descriptor_from_msg, prediction_to_msg, stamp_to_ns
from .parameters import NodeParameters
from .qos import qos_of

__all__ = ["ClassifierNode", "default_model_folder", "main", "layout_mismatch"]


def default_model_folder(node_name: str, namespace: str = "/", robot: str = "") -> Path:
    """``$ROS_HOME/tactile_descriptors_ros/[<robot>/][<namespace>/]<node_name>/`` (``ROS_HOME``: ``~/.ros``).

    Each robot, namespace and node has its own folder (a NAO's and a Shadow
    Hand's ``classifier_node``, or ``/left`` and ``/right``, never share a
    model); inside it, one model file per descriptor layout
    (:func:`~tactile_descriptors_ros.core.model_store.layout_file_name`).
    """
    home = Path(os.environ.get("ROS_HOME") or Path.home() / ".ros")
    folder = home / "tactile_descriptors_ros"
    if robot:
        folder = folder / robot
    for part in namespace.strip("/").split("/"):
        if part:
            folder = folder / part
    return folder / node_name


def _model_path(value: str, default_folder: Path) -> str:
    """``model_path`` as used: a file, or a folder ending in the path separator ('' = ``default_folder``)."""
    if not value:
        return f"{default_folder}{os.sep}"
    path = str(Path(os.path.expanduser(value)))
    return f"{path}{os.sep}" if value.endswith(("/", os.sep)) else path


@dataclass(frozen=True)
class _Predicted:
    """A descriptor the protocol keeps for its label, with the class predicted before the label came."""

    sample: DescriptorSample
    prediction: str | None


def layout_mismatch(sample: DescriptorSample, model_labels: Sequence[str], advice: str = "") -> str:
    """Why a model refuses a descriptor: both feature-group selections, value counts and body parts."""
    return (f"descriptor of feature groups {selection_name(groups_in_labels(sample.labels))} "
            f"({len(sample.labels)} values, {sample.robot} {'/'.join(sample.body_parts)}) does not fit the model, "
            f"trained on feature groups {selection_name(groups_in_labels(model_labels))} ({len(model_labels)} "
            f"values){'; ' + advice if advice else ''}")


class ClassifierNode(StopsQuietly, Node):
    """The classifier node; ``kwargs`` go to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``)."""

    #: ``~/label`` is a coroutine that awaits the learning (:func:`~.common.spin` refuses an executor that
    #: does not await it)
    coroutine_callbacks = True

    def __init__(self, node_name: str = "classifier_node", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        from rclpy.callback_groups import ReentrantCallbackGroup
        from rclpy.event_handler import SubscriptionEventCallbacks
        from std_srvs.srv import Trigger

        from tactile_descriptors_msgs.msg import Descriptor, DescriptorLayout, Label, Prediction
        from tactile_descriptors_msgs.srv import LearnLabel

        # set first: destroy_node releases them, also after a constructor that raised (a refused parameter)
        self.store: ModelStore | None = None
        self.folder_lock: ModelLock | None = None
        self.holder = self.get_fully_qualified_name()
        self.params = params = NodeParameters(self, CLASSIFIER_NODE)
        robot_arg = params.declare("robot")
        self.robot_name = load_robot(robot_arg).name if robot_arg else ""
        folder = default_model_folder(self.get_name(), self.get_namespace(), self.robot_name)
        params.declare_all(resolve={"model_path": lambda p: _model_path(p, folder)})
        path = params["model_path"]
        #: the model file given, or None: one per layout in :attr:`model_folder`
        self.given_path: Path | None = Path(path) if not path.endswith(os.sep) else None
        self.model_folder: Path | None = None if self.given_path else Path(path)
        self.log_activity = params["log_activity"]
        self.standardize = params["standardize"]
        self.pa_update = params["pa_update"]
        self.pa_average = params["pa_average"]
        self.labels = LabelProtocol(params["label_horizon"], params["label_expiry_explorations"],
                                    params["max_class_name_chars"], params["max_classes"],
                                    params["max_exploration_id_step"], params["label_hold_s"])
        order = params["prediction_order"]
        self.order: StampOrder[DescriptorSample, _Predicted] = StampOrder(
            self.labels, self._predict, self._apply, params["label_wait_s"], hold_descriptors=order == "stamp",
            jump_s=params["clock_jump_s"])
        params.on_set("eta", self._set_eta)
        params.on_set("label_horizon", self._set_horizon)
        params.on_set("label_hold_s", self._set_label_hold)
        params.on_set("label_wait_s", self._set_label_wait)
        self.load_on_start = params["load_model"]
        self.enable_reset = params["enable_reset"]

        self.model: OnlineClassifier | None = None
        self.layout_error: str | None = None
        # ModelError: another node holds the file or folder, or the file is corrupt -> refuse to start
        if self.given_path is not None:
            self.store = ModelStore(self.given_path, holder=self.holder)
            self._adopt_store()
        else:
            self.folder_lock = ModelLock(self.model_folder, self.holder)
            self.folder_lock.acquire()
        self.latest: DescriptorSample | None = None
        self.counts: Counter[str] = Counter()
        self.correct_before_label = 0
        self.scored_labels = 0
        self.last_save_error: str | None = None

        qos_desc = qos_of(params, "descriptor")
        # A reliable KEEP_ALL reader replaces nothing; what a publisher's own history drops is reported by
        # DDS as lost and counted (docs/nodes.md).
        qos_label = qos_of(params, "label")
        qos_pred = qos_of(params, "prediction")
        self.pub = self.create_publisher(Prediction, PREDICTION_TOPIC, qos_pred)
        self.sub_desc = self.create_subscription(
            Descriptor, DESCRIPTOR_TOPIC, self._on_descriptor, qos_desc,
            event_callbacks=SubscriptionEventCallbacks(message_lost=lambda e: self._lost("descriptors_lost", e)))
        # the labels of the descriptors' values, sent once per layout on the (latched) layout topic; a descriptor
        # that arrives before its layout waits for it (at most LAYOUT_WAIT_S, at most label_horizon of them)
        self.layouts = DescriptorLayouts(max_held=params["label_horizon"], wait_s=self.LAYOUT_WAIT_S)
        self.sub_layout = self.create_subscription(DescriptorLayout, layout_topic(self.sub_desc.topic_name),
                                                   self._on_layout, qos_of(params, "layout"))
        self.sub_label = self.create_subscription(
            Label, LABEL_TOPIC, self._on_label, qos_label,
            event_callbacks=SubscriptionEventCallbacks(message_lost=lambda e: self._lost("labels_lost", e)))
        # a call waits (a coroutine) until its label is decided; in its own reentrant group, so that the waiting
        # calls never hold back the descriptors and labels they wait for
        self.srv_label = self.create_service(LearnLabel, "~/label", self._srv_label,
                                             callback_group=ReentrantCallbackGroup())
        self.srv_save = self.create_service(Trigger, "~/save", self._srv_save)
        self.srv_reset = self.create_service(Trigger, "~/reset", self._srv_reset)
        self.diagnostics = Diagnostics(self, params["diagnostics_period_s"])
        self.diagnostics.add("classifier", self._status)
        # what waits in stamp order is released when its wait runs out, even if nothing else arrives
        self.order_timer = self.create_timer(0.05, self._poll)
        params.finish()
        where = self.given_path or self.model_folder / "<layout>.json"
        self.get_logger().info(f"model file {where}; predictions on {self.pub.topic_name} "
                               f"({order} prediction order); ~/reset {'enabled' if self.enable_reset else 'disabled'}")

    @property
    def model_path(self) -> Path:
        """The model file in use (with ``model_path`` '', the layout's file once known, else the folder)."""
        if self.store is not None:
            return self.store.path
        return self.given_path or self.model_folder

    # ------------------------------------------------------------- parameters
    def _set_eta(self, values, changed):
        """``ros2 param set ... eta``: the model learns with the new aggressiveness from its next update (a model
        loaded from a file keeps its own until then)."""
        value = values["eta"]

        def apply() -> None:
            if self.model is not None:
                self.model.pa.eta = value

        return apply

    def _set_horizon(self, values, changed):
        """``ros2 param set ... label_horizon``: a smaller horizon forgets the oldest kept descriptors now."""
        value = values["label_horizon"]

        def apply() -> None:
            for decision in self.labels.set_horizon(value):
                self._apply(decision)

        return apply

    def _set_label_hold(self, values, changed):
        """``ros2 param set ... label_hold_s``: held labels expire after the new time from the next poll on."""
        value = values["label_hold_s"]
        return lambda: setattr(self.labels, "hold_s", value)

    def _set_label_wait(self, values, changed):
        """``ros2 param set ... label_wait_s``: from the next message (or poll) on."""
        value = values["label_wait_s"]
        return lambda: self.order.set_wait(value)

    # ------------------------------------------------------------------ model
    def _adopt_store(self) -> None:
        """Open the store (lock, stray temp files, load): raises ModelError for a held or corrupt file."""
        self.model = self.store.open(load=self.load_on_start)
        if self.store.strays_removed:
            self.get_logger().info(f"removed a temporary file of a killed rewrite: "
                                   f"{', '.join(map(str, self.store.strays_removed))}")
        if self.store.compaction_error:
            self.get_logger().warning(f"model loaded, but not compacted ({self.store.compaction_error}); new "
                                      "labels go to its journal")
        if self.model is not None:
            self.labels.known_classes(self.model.classes)
            self.get_logger().info(f"loaded model {self.store.path}: {len(self.model.classes)} classes "
                                   f"({', '.join(self.model.classes)}), {self.model.pa.updates} updates")

    def _new_model(self, labels) -> OnlineClassifier:
        """An empty model of a descriptor layout, with this node's learning parameters."""
        return OnlineClassifier(labels, eta=self.params["eta"], log_activity=self.log_activity,
                                standardize=self.standardize, update=self.pa_update, average=self.pa_average)

    def _model_for(self, sample: DescriptorSample) -> OnlineClassifier:
        """The model descriptors of this layout are predicted with (opening the layout's file with a default path)."""
        if self.store is None:
            self.store = ModelStore(self.model_folder / layout_file_name(sample.labels), holder=self.holder)
            self._adopt_store()
        if self.model is None:
            self.model = self._new_model(sample.labels)
        return self.model

    #: longest wait of a descriptor for its layout [s]
    LAYOUT_WAIT_S = 10.0

    def _poll(self) -> None:
        """Timer: release what waits in stamp order past its wait; drop descriptors whose layout never came."""
        now = time.monotonic()
        for msg in self.layouts.expire(now):
            self.get_logger().warning(
                f"descriptor of exploration {msg.exploration_id} names layout {msg.layout_id!r}, which did not come "
                f"on {self.sub_layout.topic_name} within {self.LAYOUT_WAIT_S:g} s: dropped", throttle_duration_sec=5.0)
        self.order.poll(now)

    def _on_layout(self, msg) -> None:
        """A ``DescriptorLayout``: learn its labels, then take the descriptors that waited for it."""
        held = self.layouts.add(msg)
        if msg.layout_id not in self.layouts.labels:
            self.get_logger().warning(f"layout {msg.layout_id!r} refused: its id is not the id of its labels",
                                      throttle_duration_sec=5.0)
        for waiting in held:
            self._on_descriptor(waiting)

    # ------------------------------------------------------------ descriptors
    def _on_descriptor(self, msg) -> None:
        labels = self.layouts.of(msg)
        if labels is None:
            self.layouts.hold(msg, time.monotonic())
            return
        try:
            sample = descriptor_from_msg(msg, labels)
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
        model = self._model_for(sample)
        if sample.labels != model.labels:
            self.counts["layout_mismatch"] += 1
            advice = ("give this node another model_path, or '' for one model per descriptor layout"
                      if self.given_path else "two layouts reach one classifier: give each window node's "
                      "descriptors a classifier of their own (another namespace)")
            self.layout_error = layout_mismatch(sample, model.labels, f"{advice} (model file {self.model_path})")
            self.get_logger().error(self.layout_error, throttle_duration_sec=5.0)
            return None
        self.layout_error = None
        # the kept descriptors (label_horizon of them) share the model's labels: one copy, not one per
        # descriptor (a NAO descriptor's 917 label strings are about 80 kB; the node grew by that per touch)
        sample = replace(sample, labels=model.labels)
        model.observe(sample.values)
        name, scores = model.predict(sample.values)
        self.pub.publish(prediction_to_msg(sample, class_name=name, class_names=model.classes, scores=scores,
                                           model_version=model.version, updates=model.pa.updates,
                                           frame_id=self.params["frame_id"]))
        self.counts["predictions"] += 1
        self.latest = sample
        return _Predicted(sample, name)

    # ----------------------------------------------------------------- labels
    def _on_label(self, msg) -> None:
        self.counts["labels_received"] += 1
        self.order.add_label(int(msg.exploration_id), str(msg.class_name), stamp_to_ns(msg.header.stamp),
                             time.monotonic())

    def _lost(self, key: str, event) -> None:
        """DDS reports samples a publisher dropped before this node took them (a burst beyond its history)."""
        self.counts[key] += int(event.total_count_change)
        self.get_logger().warning(f"{key.replace('_', ' ')}: {self.counts[key]} so far (the publisher's history "
                                  "overflowed; use a deeper one, or ~/label)", throttle_duration_sec=5.0)

    async def _srv_label(self, request, response):
        """``~/label``: one label, answered once it is learned and saved (or refused, expired, dropped)."""
        from rclpy.task import Future

        self.counts["labels_received"] += 1
        done = Future()
        self.order.add_label(int(request.exploration_id), str(request.class_name),
                             stamp_to_ns(request.header.stamp), time.monotonic(), token=done)
        outcome = await done
        for key, value in outcome.items():
            setattr(response, key, value)
        return response

    def _apply(self, decision: LabelDecision) -> None:
        """Carry out a :class:`~..core.labels.LabelDecision`: learn, or log a hold, refusal or expiry."""
        answer: dict = {"exploration_id": int(decision.exploration_id), "class_name": decision.class_name,
                        "reason": decision.reason or "", "message": decision.message}
        if decision.action == LEARN:
            answer.update(self._learn(decision.item, decision.class_name))
        elif decision.action == HELD:
            self.get_logger().info(decision.message, throttle_duration_sec=1.0)
            return  # answered when it is learned or expires
        else:
            self.get_logger().warning(decision.message, throttle_duration_sec=1.0)
            dropped = decision.action == EXPIRED and "dropped" in (decision.reason or "")
            answer["outcome"] = "dropped" if dropped else decision.action
        if decision.token is not None and not decision.token.done():
            answer.setdefault("success", False)
            answer.setdefault("saved", False)
            answer["model_version"] = self.model.version if self.model is not None else 0
            decision.token.set_result(answer)

    def _learn(self, kept: _Predicted, name: str) -> dict:
        """Learn one label; what to answer: ``success`` (learned), ``saved`` (durable), the log line."""
        sample = kept.sample
        if self.model is None or sample.labels != self.model.labels:  # the model was reset to another layout meanwhile
            self.counts["layout_mismatch"] += 1
            return {"outcome": REFUSED, "reason": "layout_mismatch",
                    "message": f"label {name!r}: the model was reset to another descriptor layout meanwhile"}
        self.scored_labels += 1
        self.correct_before_label += int(kept.prediction == name)
        new_class = name not in self.model.classes
        loss = self.model.learn(sample.values, name)
        self.counts["updates"] += 1
        saved = self._record() if self.params["save_after_update"] else None
        text = (f"learned exploration {sample.exploration_id}: {name!r}{' (new class)' if new_class else ''}, "
                f"loss {loss:.3f}, {len(self.model.classes)} classes")
        if saved is False:  # _record logged the error: in memory only, never reported as saved
            return {"outcome": "learned", "success": True, "saved": False,
                    "message": f"{text}, NOT saved: {self.last_save_error}"}
        self.get_logger().info(f"{text}{', saved' if saved else ''}")
        return {"outcome": "learned", "success": True, "saved": bool(saved), "message": text}

    def _record(self) -> bool:
        """Make the last update durable (journal entry, synced); False and an error when it failed."""
        failures = self.store.compaction_failures
        try:
            self.store.record(self.model)
        except ModelError as exc:
            self.counts["save_failed"] += 1
            self.last_save_error = str(exc)
            self.get_logger().error(f"update learned in memory but not saved: {exc}")
            return False
        self.last_save_error = None
        if self.store.compaction_failures > failures:
            self.get_logger().warning(f"the label is saved in the journal, but compacting the model failed: "
                                      f"{self.store.compaction_error}", throttle_duration_sec=60.0)
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
        if not self.enable_reset:
            self.counts["reset_refused"] += 1
            response.success = False
            response.message = ("~/reset is disabled: it erases the model, and anyone on the ROS domain could call "
                                "it; start the node with enable_reset:=true to allow it")
            self.get_logger().warning(response.message, throttle_duration_sec=5.0)
            return response
        labels = self.latest.labels if self.latest is not None else None
        self.model = None
        self.layout_error = None
        self.order.reset()
        self.latest = None
        self.correct_before_label = self.scored_labels = 0
        try:
            if labels is not None and self.given_path is not None:
                self.model = self._new_model(labels)
                self.store.save(self.model)
            elif self.store is not None:
                self.store.reset()
                if self.given_path is None:  # the next descriptor opens its layout's file anew
                    self.store.close()
                    self.store = None
        except ModelError as exc:
            response.success, response.message = False, f"model reset in memory, but {exc}"
            return response
        self.counts["resets"] += 1
        response.success, response.message = True, f"model reset ({self.model_path})"
        self.get_logger().info(response.message)
        return response

    def close(self) -> None:
        """At shutdown: compact the journal into the model file (a clean stop leaves one file), release the locks."""
        if self.store is not None and self.model is not None and self.params["save_after_update"] \
                and self.store.journal.exists():
            self._save()
        self._release()

    def _release(self) -> None:
        if self.store is not None:
            self.store.close()
        if self.folder_lock is not None:
            self.folder_lock.release()

    def destroy_node(self) -> None:
        """Release the model's locks (without compacting: :meth:`close` does that) and destroy the node."""
        self._release()
        super().destroy_node()

    # ------------------------------------------------------------ diagnostics
    @property
    def online_accuracy(self) -> float:
        """Accuracy of the predictions made before their label arrived (NaN before any)."""
        return self.correct_before_label / self.scored_labels if self.scored_labels else float("nan")

    def _status(self) -> Status:
        store = self.store
        values = {"model_path": str(self.model_path), "classes": len(self.model.classes) if self.model else 0,
                  "class_names": ", ".join(self.model.classes) if self.model else "",
                  "updates": self.model.pa.updates if self.model else 0,
                  "model_version": self.model.version if self.model else 0,
                  "labelled_predictions": self.scored_labels, "online_accuracy": self.online_accuracy,
                  "kept_descriptors": self.labels.kept, "pending_labels": self.labels.held,
                  "waiting_in_stamp_order": self.order.waiting,
                  "compactions": store.compactions if store else 0,
                  "compaction_failures": store.compaction_failures if store else 0,
                  "layouts": len(self.layouts.labels), "waiting_for_layout": self.layouts.held,
                  "unknown_layout": self.layouts.unknown, "bad_layout": self.layouts.bad}
        values.update({k: v for k, v in sorted((self.counts + self.labels.counts + self.order.counts).items())})
        if self.layout_error:
            return Status("error", self.layout_error, values)
        if self.last_save_error:
            return Status("error", self.last_save_error, values)
        if store is not None and store.compaction_error:
            return Status("warn", f"labels are saved in the journal, but compacting failed: {store.compaction_error}",
                          values)
        refused = {k: v for k, v in sorted(self.labels.counts.items()) if v and k not in ("labels_learned",
                                                                                          "early_labels")}
        if self.layouts.unknown or self.layouts.bad:
            return Status("warn", f"{self.layouts.unknown} descriptors whose layout never came on "
                                  f"{self.sub_layout.topic_name}, {self.layouts.bad} layouts refused", values)
        lost = {k: self.counts[k] for k in ("labels_lost", "descriptors_lost", "reset_refused") if self.counts[k]}
        if refused or lost or self.counts["malformed_descriptor"]:
            what = ", ".join(f"{k}={v}" for k, v in {**refused, **lost}.items())
            return Status("warn", f"labels not learned: {what or 'none'}; "
                                  f"{self.counts['malformed_descriptor']} malformed descriptors", values)
        return Status("ok", f"{values['classes']} classes, {values['updates']} updates", values)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``classifier_node`` executable."""
    return run_node(ClassifierNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
