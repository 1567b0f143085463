"""The ``classifier_node`` PROCESS killed with SIGKILL right after a label, then restarted.

Guarantee under test (the same as the library-level test in ``test_hard_faults.py``, now through the
real node, DDS and its save-after-every-update path): every label the node reported ("learned
exploration N" in its log) and every label seen saved (the model's ``version``, file and journal, reaching
the number of labels sent) is in the model the restarted node loads; the model is never torn (it always
loads, and its classes, ``version`` and ``updates`` agree); the label sent just before the kill is either
fully in the model or fully absent; and the restarted node predicts with the reloaded model and keeps
learning.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from descriptor_msgs import LABELS, descriptor_msg

pytestmark = [pytest.mark.ros, pytest.mark.slow]

_REPO = Path(__file__).resolve().parents[2]
_N_CONFIRMED = 4  # labels whose save we wait for before the kill


def _class(eid: int) -> str:
    return f"mat_{eid}"  # one class per exploration: a label's presence is its class's presence


def _file_state(path: Path) -> dict | None:
    """The model file as JSON (None while it does not exist); a torn file fails the json parse."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    return json.loads(text)


class _Node:
    """One ``classifier_node`` process we start (and only ever kill by its own PID)."""

    def __init__(self, ns: str, model_path: Path, env: dict[str, str], log: Path, load_model: bool) -> None:
        cmd = [sys.executable, "-m", "tactile_descriptors_ros.nodes.classifier_node", "--ros-args",
               "-r", f"__ns:=/{ns}", "-p", f"model_path:={model_path}", "-p", "save_after_update:=true",
               "-p", f"load_model:={'true' if load_model else 'false'}", "-p", "diagnostics_period_s:=5.0"]
        self.log = log
        self._fh = open(log, "w")
        self.proc = subprocess.Popen(cmd, stdout=self._fh, stderr=subprocess.STDOUT, env=env, cwd=_REPO)

    def tail(self, n: int = 30) -> str:
        self._fh.flush()
        return "\n".join(self.log.read_text(errors="replace").splitlines()[-n:])

    def kill(self) -> int:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        code = self.proc.wait(timeout=30)
        self._fh.close()
        return code

    def stop(self) -> None:
        """Clean-up: SIGINT, then SIGKILL if it does not exit (our own PID only)."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10)
        if not self._fh.closed:
            self._fh.close()


def test_classifier_node_sigkilled_after_a_label_reloads_every_saved_label(tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction
    from tactile_descriptors_ros.core.model_store import load_model as load_saved

    rng = np.random.default_rng(7)
    model_path = tmp_path / "model.json"
    ns = f"sigkill_{uuid.uuid4().hex[:8]}"  # own namespace: no cross-talk even if the domain id collides
    domain = random.randint(1, 100)
    env = dict(os.environ)
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain),
               ROS_LOG_DIR=os.environ.get("ROS_LOG_DIR", str(_REPO / "build" / "ros_log")),
               PYTHONPATH=os.pathsep.join(p for p in (str(_REPO), os.environ.get("PYTHONPATH", "")) if p))

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("sigkill_test_io", context=context)
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    preds: list = []
    node.create_subscription(Prediction, f"/{ns}/tactile/prediction", preds.append, qos)
    pub_desc = node.create_publisher(Descriptor, f"/{ns}/tactile/descriptor", qos)
    pub_label = node.create_publisher(Label, f"/{ns}/tactile/label", qos)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)

    def spin_until(cond, timeout_s: float, proc: _Node) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not cond():
            assert proc.proc.poll() is None, f"classifier_node exited ({proc.proc.returncode}):\n{proc.tail()}"
            ex.spin_once(timeout_sec=0.05)
        return bool(cond())

    topics = {"sub": [f"/{ns}/tactile/descriptor", f"/{ns}/tactile/label"], "pub": [f"/{ns}/tactile/prediction"]}

    def endpoint_gids() -> dict[str, set[bytes]]:
        return {t: {bytes(i.endpoint_gid) for i in node.get_subscriptions_info_by_topic(t)} for t in topics["sub"]} \
            | {t: {bytes(i.endpoint_gid) for i in node.get_publishers_info_by_topic(t)} for t in topics["pub"]}

    def connected(proc: _Node, old: dict[str, set[bytes]]) -> None:
        """Wait until this process's own endpoints are discovered: a SIGKILLed node's endpoints stay in
        the graph until their DDS lease expires, so a plain count would match the dead node."""
        ok = spin_until(lambda: all(gids - old.get(t, set()) for t, gids in endpoint_gids().items()), 60.0, proc)
        assert ok, f"classifier_node not discovered within 60 s:\n{proc.tail()}"
        time.sleep(1.0)  # let the node's side of discovery settle too (machine may be loaded)

    def version() -> int:
        """The saved model's version: the file with its journal replayed (-1 before the first save)."""
        if _file_state(model_path) is None:
            return -1
        return load_saved(model_path).version

    first = _Node(ns, model_path, env, tmp_path / "first.log", load_model=False)
    second: _Node | None = None
    try:
        # ---- first life: N labels, each confirmed saved (the file's version reaches it)
        connected(first, {})
        for eid in range(1, _N_CONFIRMED + 1):
            pub_desc.publish(descriptor_msg(eid, rng))
            pub_label.publish(Label(exploration_id=eid, class_name=_class(eid)))
            assert spin_until(lambda eid=eid: version() >= eid, 60.0, first), \
                f"label {eid} not saved within 60 s (file version {version()}):\n{first.tail()}"
        assert version() == _N_CONFIRMED
        # the node predicts before it learns, but its predictions may still be on their way to this executor
        assert spin_until(lambda: {p.exploration_id for p in preds} >= set(range(1, _N_CONFIRMED + 1)), 30.0,
                          first), f"predictions {sorted({p.exploration_id for p in preds})}:\n{first.tail()}"

        before_kill = endpoint_gids()

        # ---- one more label, then SIGKILL at once: it may or may not have been learned and saved
        last = _N_CONFIRMED + 1
        pub_desc.publish(descriptor_msg(last, rng))
        pub_label.publish(Label(exploration_id=last, class_name=_class(last)))
        # kill the moment the node reports the label (or after 5 s without a report): a node that logged before
        # its save finished would lose a reported label here
        marker = f"learned exploration {last}"
        deadline = time.monotonic() + 5.0
        while marker not in first.log.read_text(errors="replace") and time.monotonic() < deadline:
            time.sleep(0.0005)  # polling the log file as fast as it can be read; no ROS spinning needed
        code = first.kill()
        assert code == -signal.SIGKILL, f"exit code {code}:\n{first.tail()}"
        reported = {int(m) for m in re.findall(r"learned exploration (\d+)", first.log.read_text(errors="replace"))}
        assert reported >= set(range(1, _N_CONFIRMED + 1)), reported

        # ---- the file after the kill: valid JSON, loads, self-consistent, holds every confirmed label
        state = _file_state(model_path)
        assert state is not None
        model = load_saved(model_path)
        v = model.version
        assert v in (_N_CONFIRMED, last), v                      # nothing saved was lost, nothing invented
        assert model.pa.updates == v and len(model.classes) == v
        assert model.classes == [_class(e) for e in range(1, v + 1)]  # all confirmed; the last fully or not at all
        assert {_class(e) for e in reported} <= set(model.classes)  # no reported label lost
        assert model.labels == tuple(LABELS)

        # ---- second life: loads that model, predicts with it, keeps learning and saving
        preds.clear()
        second = _Node(ns, model_path, env, tmp_path / "second.log", load_model=True)
        connected(second, before_kill)
        probe = 100
        probe_msg = descriptor_msg(probe, rng)
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not any(p.exploration_id == probe for p in preds):
            pub_desc.publish(probe_msg)  # unlabelled and the same exploration: repeating it changes no label
            spin_until(lambda: any(p.exploration_id == probe for p in preds), 3.0, second)
        assert any(p.exploration_id == probe for p in preds), \
            f"no prediction from the restarted node within 60 s:\n{second.tail()}"
        p = next(p for p in preds if p.exploration_id == probe)
        assert p.has_model and p.class_name in model.classes
        assert list(p.class_names) == model.classes
        assert p.updates == v and p.model_version == v

        pub_label.publish(Label(exploration_id=probe, class_name="after_restart"))
        assert spin_until(lambda: version() >= v + 1, 60.0, second), \
            f"the restarted node did not save its new label (file version {version()}):\n{second.tail()}"
        pub_desc.publish(descriptor_msg(probe + 1, rng))
        assert spin_until(lambda: any(p.exploration_id == probe + 1 for p in preds), 60.0, second)
        p2 = next(p for p in preds if p.exploration_id == probe + 1)
        assert list(p2.class_names) == model.classes + ["after_restart"] and p2.updates == v + 1
        again = load_saved(model_path)
        assert again.classes == model.classes + ["after_restart"] and again.version == v + 1
    finally:
        first.stop()
        if second is not None:
            second.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
