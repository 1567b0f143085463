"""The ``classifier_node`` PROCESS and its model file: a full disk at compaction, more labels, a kill, a restart;
two nodes on one model file.

The full disk is fault-injected into the node's process (a ``sitecustomize`` module on its ``PYTHONPATH``, no
hook in the package): while a marker file exists, every rewrite of the model file fails with ENOSPC, as on a
full disk, and the journal keeps its reserved space.  Labels go through ``~/label``, whose answer says whether
each one was saved: every label answered ``saved`` must be in the model the restarted node loads.
"""

from __future__ import annotations

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

pytestmark = [pytest.mark.ros, pytest.mark.slow]

_REPO = Path(__file__).resolve().parents[2]
_N_VALUES = 500  # a wide descriptor: each journal entry is ~66 kB, so the journal passes 1 MiB in ~16 labels


class _Node:
    """One ``classifier_node`` process we start (and only ever signal by its own PID)."""

    def __init__(self, ns: str, model_path: Path, env: dict[str, str], log: Path) -> None:
        cmd = [sys.executable, "-m", "tactile_descriptors_ros.nodes.classifier_node", "--ros-args",
               "-r", f"__ns:=/{ns}", "-p", f"model_path:={model_path}", "-p", "diagnostics_period_s:=5.0",
               # the journal's sizes below are a first-order learner's (two weight rows an entry; AROW adds
               # a covariance step to each entry and an n x n matrix to the file)
               "-p", "pa_update:=max_loss", "-p", "pa_average:=true"]
        self.log = log
        self._fh = open(log, "w")
        self.proc = subprocess.Popen(cmd, stdout=self._fh, stderr=subprocess.STDOUT, env=env, cwd=_REPO)

    def text(self) -> str:
        self._fh.flush()
        return self.log.read_text(errors="replace")

    def wait_for(self, line: str, timeout_s: float = 120.0) -> None:
        deadline = time.monotonic() + timeout_s
        while line not in self.text():
            assert self.proc.poll() is None, f"classifier_node exited ({self.proc.returncode}):\n{self.text()}"
            assert time.monotonic() < deadline, f"no {line!r} in the node's log:\n{self.text()[-3000:]}"
            time.sleep(0.05)  # polling the log file: the event is the line appearing

    def kill(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=30)

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10)
        if not self._fh.closed:
            self._fh.close()


def _env(tmp_path: Path) -> tuple[dict[str, str], int]:
    domain = random.randint(1, 100)
    env = dict(os.environ)
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain), ROS_HOME=str(tmp_path / "home"),
               ROS_LOG_DIR=os.environ.get("ROS_LOG_DIR", str(_REPO / "build" / "ros_log")),
               PYTHONPATH=os.pathsep.join(p for p in (str(_REPO), os.environ.get("PYTHONPATH", "")) if p))
    return env, domain


def test_two_classifier_nodes_on_one_model_file_the_second_refuses_naming_the_first(tmp_path):
    env, _ = _env(tmp_path)
    model = tmp_path / "model.json"
    left = _Node("left", model, env, tmp_path / "left.log")
    right = None
    try:
        left.wait_for(f"model file {model}")
        right = _Node("right", model, env, tmp_path / "right.log")
        assert right.proc.wait(timeout=120) == 2, right.text()
        text = right.text()
        assert f"model {model} is in use by /left/classifier_node (pid {left.proc.pid} on " in text, text
        assert "[FATAL]" in text and "Traceback" not in text
        assert left.proc.poll() is None  # the first one is untouched
    finally:
        left.stop()
        if right is not None:
            right.stop()


def _wide_descriptor(eid: int, rng: np.random.Generator):
    from tactile_descriptors_msgs.msg import Descriptor

    msg = Descriptor()
    msg.robot, msg.exploration_id = "shadow_hand", eid
    msg.window_mode, msg.layout_mode, msg.channel_mode = "exploration", "concat", "averaged"
    msg.window_start.sec, msg.window_end.sec = 10 * eid, 10 * eid + 2
    msg.header.stamp = msg.window_end
    msg.body_parts, msg.contact, msg.cells_in_contact, msg.cells_total = ["index"], [True], [1], [1]
    msg.mean_force_n, msg.quality = [2.0], [0]
    msg.labels = [f"index/v{i}" for i in range(_N_VALUES)]
    msg.values = rng.uniform(0.5, 5.0, _N_VALUES).tolist()
    return msg


_FULL_DISK = """
import errno
import os


def _inject():
    from tactile_descriptors_ros.core import model_store

    write_all = model_store._write_all

    def full_disk(fd, data):
        if os.path.exists(os.environ["TACTILE_TEST_FULL_DISK"]):
            raise OSError(errno.ENOSPC, "No space left on device")
        write_all(fd, data)

    model_store._write_all = full_disk


_inject()
"""


def test_a_full_disk_at_compaction_more_labels_a_kill_and_a_restart_keep_every_saved_label(tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, Prediction
    from tactile_descriptors_msgs.srv import LearnLabel
    from tactile_descriptors_ros.core.model_store import load_model

    env, domain = _env(tmp_path)
    inject = tmp_path / "inject"
    inject.mkdir()
    (inject / "sitecustomize.py").write_text(_FULL_DISK)
    full = tmp_path / "disk_is_full"
    env["PYTHONPATH"] = os.pathsep.join((str(inject), env["PYTHONPATH"]))
    env["TACTILE_TEST_FULL_DISK"] = str(full)
    ns = f"disk_{uuid.uuid4().hex[:8]}"
    disk = tmp_path / "disk"
    model = disk / "model.json"
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    io = rclpy.create_node("disk_test_io", context=context)
    keep_all = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    preds: list = []
    io.create_subscription(Prediction, f"/{ns}/tactile/prediction", preds.append, keep_all)
    desc = io.create_publisher(Descriptor, f"/{ns}/tactile/descriptor", keep_all)
    client = io.create_client(LearnLabel, f"/{ns}/classifier_node/label")
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(io)
    rng = np.random.default_rng(0)
    node = second = third = None

    def spin_until(cond, proc: _Node, timeout_s: float = 120.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not cond():
            assert proc.proc.poll() is None, f"classifier_node exited ({proc.proc.returncode}):\n{proc.text()}"
            ex.spin_once(timeout_sec=0.05)
        return bool(cond())

    def label(eid: int, proc: _Node):
        """One exploration described and labelled through ~/label; the answer (learned, saved)."""
        msg = _wide_descriptor(eid, rng)
        deadline = time.monotonic() + 120.0
        while not any(p.exploration_id == eid for p in preds):
            # a restarted node's reader may not have matched this writer yet (the killed node's endpoints linger
            # in discovery): published again until its prediction comes; the same exploration again is harmless
            assert time.monotonic() < deadline, f"no prediction for {eid}:\n{proc.text()[-2000:]}"
            desc.publish(msg)
            spin_until(lambda: any(p.exploration_id == eid for p in preds), proc, 2.0)
        future = client.call_async(LearnLabel.Request(exploration_id=eid, class_name=f"m{eid % 7}"))
        assert spin_until(future.done, proc), f"no answer for {eid}:\n{proc.text()[-2000:]}"
        return future.result()

    try:
        node = _Node(ns, model, env, tmp_path / "first.log")
        assert spin_until(lambda: desc.get_subscription_count() >= 1 and client.service_is_ready()
                          and io.count_publishers(f"/{ns}/tactile/prediction") >= 1, node)
        saved = []
        first = label(1, node)
        assert (first.success, first.saved) == (True, True)
        saved.append(1)
        first_file = model.read_bytes()
        full.touch()  # the disk fills: from the label whose entry takes the journal past 1 MiB on, the
        # compaction that follows fails, and the labels go on into the journal
        eid, answers = 1, {}
        while node.text().count("compacting the model failed") < 1 or len(answers) < 25:
            eid += 1
            answers[eid] = label(eid, node)
            assert answers[eid].success and answers[eid].saved and eid < 100, node.text()[-3000:]
        saved += list(answers)
        failed_at = int(re.search(r"compacting the model failed.*\n.*learned exploration (\d+): .*, saved",
                                  node.text()).group(1))
        assert failed_at < max(saved) and model.read_bytes() == first_file  # the file never changed
        assert not [p for p in disk.iterdir() if p.name.endswith(".tmp")]
        node.kill()
        # a restart while the disk is still full: it loads every saved label, cannot compact, appends
        second = _Node(ns, model, env, tmp_path / "second.log")
        second.wait_for(f"loaded model {model}")
        assert "not compacted" in second.text()
        assert spin_until(lambda: client.service_is_ready(), second)
        for _ in range(3):
            eid += 1
            answer = label(eid, second)
            assert (answer.saved, answer.model_version) == (True, len(saved) + 1), second.text()[-3000:]
            saved.append(eid)
        second.kill()
        full.unlink()  # the disk is freed
        third = _Node(ns, model, env, tmp_path / "third.log")
        third.wait_for(f"loaded model {model}")
        loaded = load_model(model)
        assert loaded.version == len(saved) == loaded.pa.updates  # every saved label, none invented
        assert sorted(p.name for p in disk.iterdir()) == ["model.json", "model.json.lock"]  # compacted at start
        assert spin_until(lambda: client.service_is_ready(), third)
        after = label(eid + 1, third)
        assert (after.success, after.saved, after.model_version) == (True, True, len(saved) + 1)
        third.stop()
    finally:
        for proc in (node, second, third):
            if proc is not None:
                proc.stop()
        io.destroy_node()
        rclpy.try_shutdown(context=context)
