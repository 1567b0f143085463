"""An imported bag replayed through the live window and classifier node processes, with a teacher.

What ``tactile evaluate --live`` runs (see :mod:`..evaluation.live` for what it
is compared with):

* the robot's ``window_node`` and ``classifier_node`` start as their own
  processes from the robot description's node graph
  (:func:`~..launching.graph.build_graph`; the bag stands in for the
  drivers, and the views are left out), on the deployed topics (``tactile/<body
  part>/frames``, ``tactile/descriptor``, ``tactile/label``,
  ``tactile/prediction``), this process's participant with the nodes' Fast
  DDS profile (:func:`~..launching.processes.dds_environment`);
* the bag's frames are published in bag order, paced by the graph
  (:meth:`~.replay.Player.play_paced`): a trial's frames go out only after
  the previous trial's descriptor and prediction have arrived and, for a
  training trial, after the classifier has reported (``/diagnostics``,
  ``updates``) that it learned the label.  At most one trial's batches wait
  in the window node's queue, whose depth is set above that count, so no
  frame is dropped on a slow machine; the window node's ``lost_frames``
  count is checked at the end;
* the *teacher* (this process) publishes the true label of each training
  trial's window after its prediction, and only listens to the test
  trials' predictions.

The bag's own labels are not replayed.  Every prediction carries the number
of updates the model had made; it must equal the labels taught before it
(else the run is reported as out of order, never silently scored).
"""

from __future__ import annotations

import os
import random
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tactile_descriptors_ros.errors import BagError, ConfigError

__all__ = ["LiveRun", "run_live_replay"]

#: Onset and release threshold of the replay [N]: any force above zero is contact.
_ANY_FORCE_N = 1e-9


@dataclass
class LiveRun:
    """What the live graph produced for a replay, one entry per trial window (replay order)."""

    values: list[list[float]] = field(default_factory=list)
    labels: tuple[str, ...] = ()
    contact: list[bool] = field(default_factory=list)
    predictions: list[str | None] = field(default_factory=list)
    updates_before: list[int] = field(default_factory=list)
    labels_taught: int = 0
    window_node_faults: dict[str, int] = field(default_factory=dict)
    classifier_updates: int = 0
    wall_s: float = 0.0


def _nothing_delivered(player: Any, window: Mapping[str, str], body_part: str) -> str:
    """A line for a replay whose frames all went out to a matched window node that received none, else ''."""
    from tactile_descriptors_ros.nodes.window_node import frames_matched

    sent = sum(player.report.published.values()) if player is not None else 0
    if not sent or window.get("messages_received") != "0" or not frames_matched(window, body_part):
        return ""
    return (f"\nthe window node matched the player but received none of the {sent} frames messages sent: the "
            "middleware delivered nothing (both sides of the topic matched)")


class _Teacher:
    """The teacher's node: descriptors, predictions and diagnostics in; labels out."""

    def __init__(self, context: Any, window_name: str, classifier_name: str) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from tactile_descriptors_msgs.msg import Descriptor, DescriptorLayout, Label, Prediction
        from tactile_descriptors_ros.layouts import DescriptorLayouts
        from tactile_descriptors_ros.topics import DESCRIPTOR_LAYOUT_TOPIC

        self.node = rclpy.create_node("tactile_teacher", context=context)
        self.Label = Label
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.label_pub = self.node.create_publisher(Label, "tactile/label", qos)
        # Descriptors and predictions are kept for late joiners (see run_live_replay): discovery between
        # processes may match a subscription only after the first message went out.
        latched = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.cond = threading.Condition()
        self.descriptors: list[Any] = []
        self.predictions: list[Any] = []
        self.diag: dict[str, dict[str, str]] = {}
        self.diag_seq: dict[str, int] = {}
        self._names = {f"{window_name}: ": "window", f"{classifier_name}: ": "classifier"}
        self.node.create_subscription(Descriptor, "tactile/descriptor", self._on_descriptor, latched)
        self.layouts = DescriptorLayouts()
        self.node.create_subscription(DescriptorLayout, DESCRIPTOR_LAYOUT_TOPIC, self._on_layout, latched)
        self.node.create_subscription(Prediction, "tactile/prediction", self._on_prediction, latched)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)

    def _on_descriptor(self, msg: Any) -> None:
        with self.cond:
            self.descriptors.append(msg)
            self.cond.notify_all()

    def _on_layout(self, msg: Any) -> None:
        with self.cond:
            self.layouts.add(msg)
            self.cond.notify_all()

    def _on_prediction(self, msg: Any) -> None:
        with self.cond:
            self.predictions.append(msg)
            self.cond.notify_all()

    def _on_diagnostics(self, msg: Any) -> None:
        with self.cond:
            for st in msg.status:
                for prefix, who in self._names.items():
                    if st.name.startswith(prefix) and not st.name.endswith(": process"):  # the node's own
                        self.diag[who] = {kv.key: kv.value for kv in st.values}
                        self.diag_seq[who] = self.diag_seq.get(who, 0) + 1
            self.cond.notify_all()

    def wait(self, what: str, predicate, timeout_s: float) -> None:
        """Block until ``predicate()`` holds (checked at every message received); BagError on timeout."""
        with self.cond:
            if not self.cond.wait_for(predicate, timeout=timeout_s):
                raise BagError(f"live replay: no {what} within {timeout_s:.0f} s")

    def teach(self, exploration_id: int, class_name: str) -> None:
        self.label_pub.publish(self.Label(exploration_id=exploration_id, class_name=class_name))


def run_live_replay(bag: str | os.PathLike[str], trial_start_ns: Sequence[int], train: Sequence[bool],
                    class_names: Sequence[str], trial_end_ns: Sequence[int], *, robot: str = "shadow_hand",
                    body_part: str = "index", window_parameters: Mapping[str, Any] | None = None,
                    classifier_parameters: Mapping[str, Any] | None = None, queue_depth: int = 256,
                    timeout_s: float = 120.0, verbose: bool = False) -> LiveRun:
    """Replay ``bag`` through the robot's window and classifier node processes, teaching the training trials.

    Parameters
    ----------
    bag : path
        Imported by :func:`~.importer.import_biotac_slide` with every trial cropped to the window (``max_frames``).
    trial_start_ns : sequence of int
        Each trial's first frame stamp in the bag (``ImportReport.trials[k].start_ns``).
    train : sequence of bool
        Whether each trial's label is taught.
    class_names : sequence of str
        Each trial's true class.
    trial_end_ns : sequence of int
        Each trial's end (``ImportReport.trials[k].end_ns``): every exploration window must run
        exactly from its trial's start to its end.
    robot, body_part : str
        The robot description and the body part the recordings were imported onto.
    window_parameters, classifier_parameters : mapping, optional
        More node parameters (descriptor mode, PA variant).
    queue_depth : int
        The window node's frames queue depth; must exceed the batches of one trial and its gap.
    timeout_s : float
        Longest wait for any one event (node start-up included).

    Raises
    ------
    BagError
        When a node exits, an event does not come, a prediction was made with another number of
        updates than taught before it, or the window node lost frames.
    """
    from tactile_descriptors_ros.launching.processes import GraphProcesses, dds_environment, localhost_environment

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    os.environ.update(dds_environment())  # the player's participant as the nodes' (before rclpy makes it)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from tactile_descriptors_ros.bags.replay import Player, PlayOptions
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.nodes.window_node import frames_matched

    n = len(trial_start_ns)
    if not (n == len(train) == len(class_names) == len(trial_end_ns)) or n == 0:
        raise ConfigError("one start, end, split flag and class name per trial are needed")
    rob = load_robot(robot)
    # What the replay checks: the window node and the classifier, nothing else on the frames
    replayed = ("window_node", "classifier_node")
    graph = [s for s in build_graph(rob) if s.executable in replayed]
    windows = [s for s in graph if s.executable == "window_node"]
    classifiers = [s for s in graph if s.executable == "classifier_node"]
    if len(windows) != 1 or len(classifiers) != 1:
        raise ConfigError(f"the live replay needs one window node and one classifier node in {rob.name}'s graph, "
                          f"found {len(windows)} and {len(classifiers)}", key="nodes", source=rob.source)
    w_name, c_name = windows[0].name, classifiers[0].name
    tmp = tempfile.TemporaryDirectory(prefix="tactile_live_")
    overrides = {
        w_name: {
            "body_parts": [body_part],
            # One exploration per trial, exactly its frames: any force above zero is contact (the recordings
            # are tared and clipped at 0; a soft material reads 1 count, below the default thresholds), and the
            # bag's zero-force gap between trials is the release.  The evaluation describes every recorded
            # window (its contact gate is off): with this threshold so does the node.
            "window.mode": "exploration", "window.min_duration_s": 0.0,
            "contact.force_threshold_n": _ANY_FORCE_N, "contact.release_threshold_n": _ANY_FORCE_N,
            # Replay as a recorder would take it: every batch queued, none dropped.
            "qos.frames.reliability": "reliable", "qos.frames.depth": int(queue_depth),
            # Discovery between processes can match the classifier's subscription after the first
            # descriptor went out: descriptors and predictions are kept for late joiners.
            "qos.descriptor.durability": "transient_local",
            "diagnostics_period_s": 0.05,
            **dict(window_parameters or {}),
        },
        c_name: {"load_model": False, "save_after_update": False, "diagnostics_period_s": 0.02,
                 "qos.descriptor.durability": "transient_local", "qos.prediction.durability": "transient_local",
                 **dict(classifier_parameters or {})},
    }
    specs = [s for s in build_graph(rob, model_path=str(Path(tmp.name) / "model.json"), overrides=overrides)
             if s.executable in replayed]
    procs = GraphProcesses(specs, env=localhost_environment(), output=None, keep_lines=400)
    context = rclpy.Context()
    rclpy.init(context=context)
    teacher = _Teacher(context, w_name, c_name)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(teacher.node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True, name="teacher")
    run = LiveRun()
    t0 = time.monotonic()
    player = None
    try:
        procs.start()
        spinner.start()
        frames_topic = f"/tactile/{body_part}/frames"
        player = Player(str(bag), PlayOptions(topics=(frames_topic,)), context=context, node_name="tactile_live_player")

        def alive() -> None:
            dead = procs.exited()
            if dead:
                d = dead[0]
                raise BagError(f"node {d.spec.name} exited with code {d.returncode}:\n  " + "\n  ".join(d.lines[-15:]))

        def wait(what: str, predicate) -> None:
            # Wake at least every second to notice a node that died.
            deadline = time.monotonic() + timeout_s
            while True:
                alive()
                try:
                    teacher.wait(what, predicate, min(1.0, max(0.01, deadline - time.monotonic())))
                    return
                except BagError:
                    if time.monotonic() >= deadline:
                        raise BagError(f"live replay: no {what} within {timeout_s:.0f} s") from None
        # The graph is up when the window node takes frames, the classifier takes labels and both report.
        # Discovery matches each side on its own: a volatile reader that matches the player's writer only
        # after frames went out never receives them, so both sides' counts must show the match.
        wait("window node subscribed to the frames",
             lambda: all(p.get_subscription_count() > 0 for p in player.publishers.values())
             and frames_matched(teacher.diag.get("window", {}), body_part))
        wait("classifier node subscribed to labels and publishing predictions",
             lambda: teacher.label_pub.get_subscription_count() > 0
             and teacher.node.count_publishers("/tactile/prediction") > 0
             and teacher.node.count_subscribers("/tactile/descriptor") > 1 and {"window", "classifier"} <= set(teacher.diag))

        taught = 0

        def finish(k: int) -> None:
            """Wait for trial k's descriptor and prediction; teach its label if it is a training trial."""
            nonlocal taught
            wait(f"descriptor of trial window {k + 1}", lambda: len(teacher.descriptors) > k)
            d = teacher.descriptors[k]
            if len(teacher.descriptors) > k + 1:
                raise BagError(f"the window node published {len(teacher.descriptors)} descriptors after "
                               f"{k + 1} trials: windows are not one per trial")
            start = d.window_start.sec * 1_000_000_000 + d.window_start.nanosec
            end = d.window_end.sec * 1_000_000_000 + d.window_end.nanosec
            if (start, end) != (int(trial_start_ns[k]), int(trial_end_ns[k])):
                raise BagError(f"exploration {d.exploration_id} ran {start}..{end} ns, but trial window "
                               f"{k + 1} is {trial_start_ns[k]}..{trial_end_ns[k]} ns")
            run.values.append([float(v) for v in d.values])
            wait(f"layout {d.layout_id} of trial window {k + 1}", lambda: teacher.layouts.of(d) is not None)
            run.labels = teacher.layouts.of(d)
            contact = bool(any(d.contact))
            run.contact.append(contact)
            if not contact:  # the classifier ignores a window out of contact: nothing to predict or teach
                run.predictions.append(None)
                run.updates_before.append(taught)
                return
            wanted = sum(run.contact)  # one prediction per window in contact so far
            wait(f"prediction of trial window {k + 1}", lambda: len(teacher.predictions) >= wanted)
            p = teacher.predictions[-1]
            if int(p.updates) != taught:
                raise BagError(f"trial window {k + 1} was predicted after {p.updates} updates, but {taught} labels "
                               "were taught before it: the replay is out of order")
            run.predictions.append(str(p.class_name) if p.has_model else None)
            run.updates_before.append(int(p.updates))
            if train[k]:
                teacher.teach(int(d.exploration_id), class_names[k])
                taught += 1
                seen = teacher.diag_seq.get("classifier", 0)
                wait(f"classifier update for trial window {k + 1}", lambda: teacher.diag_seq.get("classifier", 0) > seen
                     and int(teacher.diag["classifier"].get("updates", "0")) >= taught)

        def explorations() -> int:
            return int(teacher.diag.get("window", {}).get("explorations", "0"))

        # The window node judges onset and release once per callback, on the newest sample (it takes every
        # waiting batch at once).  So a trial's gap goes out only after the node has seen the trial's contact
        # (its exploration count), and the next trial only after the gap closed the exploration.
        state = {"trial": -1, "onset_seen": True}

        def before(msg: Any) -> bool:
            k, t = state["trial"], msg.log_time_ns
            if k >= 0 and not state["onset_seen"] and t > trial_end_ns[k]:
                wait(f"contact onset of trial window {k + 1}", lambda: explorations() > k)
                state["onset_seen"] = True
            if k + 1 < n and t > trial_start_ns[k + 1]:
                if k >= 0:
                    finish(k)
                state["trial"], state["onset_seen"] = k + 1, False
            return True

        player.play_paced(before)
        if state["trial"] != n - 1 or not state["onset_seen"]:
            raise BagError(f"the bag held {state['trial'] + 1} of {n} trials, or no gap after the last")
        finish(n - 1)
        run.labels_taught = taught
        # The window node's fault counters after the last window: one report published after it.
        seen = teacher.diag_seq.get("window", 0)
        wait("window node diagnostics", lambda: teacher.diag_seq.get("window", 0) > seen + 1)
        faults = {k[len("fault_"):]: int(float(v)) for k, v in teacher.diag["window"].items() if k.startswith("fault_")}
        run.window_node_faults = faults
        run.classifier_updates = int(teacher.diag["classifier"].get("updates", "0"))
        bad = {k: v for k, v in faults.items() if v}
        if bad:
            raise BagError("the window node counted faults during the replay: "
                           + ", ".join(f"{k} {v}" for k, v in sorted(bad.items())))
    except BagError as exc:
        tails = "\n".join(f"[{node.spec.name}] {line}" for node in procs.nodes for line in node.lines[-12:])
        raise BagError(f"{exc}{_nothing_delivered(player, teacher.diag.get('window', {}), body_part)}\n"
                       f"last lines of the nodes:\n{tails}\nlast diagnostics: {teacher.diag}") from None
    finally:
        run.wall_s = time.monotonic() - t0
        stop.set()
        if spinner.is_alive():
            spinner.join()
        if player is not None:
            player.destroy()
        procs.stop()
        if verbose:
            for node in procs.nodes:
                for line in node.lines[-20:]:
                    print(f"[{node.spec.name}] {line}")
        executor.remove_node(teacher.node)
        teacher.node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown(context=context)
        tmp.cleanup()
    return run
