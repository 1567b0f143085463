"""Sensor stamp -> Prediction latency through the ROS node graph (``tactile bench --latency``).

A probe node publishes ``SkinCellFrame`` messages for every cell of the NAO
at full rate (accelerometer 1 kHz, force 250 Hz, one message per cell per
``batch_s`` of sample time, stamped with the wall clock as a driver stamps
its samples) into the real ``window_node`` and ``classifier_node`` (fixed
windows), and records when each ``Prediction`` arrives.  By default the two
nodes run as their own processes, as ``ros2 launch`` starts them
(``in_process=True`` runs them in the probe's process instead).  Reported
per prediction:

* ``e2e``: arrival time minus the window's end stamp (what a user waits
  after the last sample of a window was taken);
* ``wait``: the part of it spent waiting for data: a fixed window closes when
  a sample later than its end plus ``lateness_s`` arrives, i.e. when the
  batch holding that sample has been acquired and published;
* ``processing``: arrival minus the time that closing batch was published
  (window cut, descriptor, classifier, two topic hops and callbacks).

``publish_lag`` -- how late batches went out compared with their
acquisition time -- is reported too: a growing lag means the probe itself
did not keep up.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

__all__ = ["measure_latency"]


def _summary(values_ms: list[float]) -> dict:
    if not values_ms:
        return {"n": 0}
    arr = np.asarray(values_ms)
    return {"n": int(arr.size), "median_ms": float(np.median(arr)), "p95_ms": float(np.percentile(arr, 95)),
            "max_ms": float(arr.max())}


def _node_process(module: str, params: dict) -> subprocess.Popen:
    """Start ``python -m <module>`` with ROS parameters (stdout/stderr to the ROS log directory)."""
    args = [sys.executable, "-m", module, "--ros-args"]
    for key, value in params.items():
        args += ["-p", f"{key}:={value}"]
    log_dir = Path(os.environ.get("ROS_LOG_DIR", tempfile.gettempdir()))
    log_dir.mkdir(parents=True, exist_ok=True)
    log = open(log_dir / f"bench_{module.rsplit('.', 1)[-1]}.log", "w", encoding="utf-8")  # noqa: SIM115
    return subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ))


def measure_latency(*, duration_s: float = 8.0, batch_s: float = 0.05, lateness_s: float = 0.05,
                    length_s: float = 2.0, hop_s: float = 0.5, robot: str = "nao", seed: int = 0,
                    in_process: bool = False, discovery_timeout_s: float = 20.0) -> dict:
    """Publish ``duration_s`` of skin frames at full rate; time each Prediction (see the module doc).

    Returns a JSON-able dict: settings, ``e2e``, ``wait``, ``processing``
    and ``publish_lag`` summaries (median, p95, max in ms) and the message
    counts.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Prediction

    from ..core.robot import load_robot
    from ..nodes.classifier_node import PREDICTION_TOPIC, ClassifierNode
    from ..nodes.conversions import SkinFrame, ns_to_stamp, skin_frame_to_msg, stamp_to_ns
    from ..nodes.window_node import FRAMES_TOPIC, WindowNode

    desc = load_robot(robot)
    cell_type = next(iter(desc.cell_types.values()))
    fs_a, fs_f = cell_type.vibration.rate_hz, cell_type.deformation.rate_hz
    n_per_count = cell_type.force.n_per_count if cell_type.force else 0.002442
    n_a = int(round(batch_s * fs_a))
    n_f = int(round(batch_s * fs_f))
    if n_a < 1 or n_f < 1:
        raise ValueError(f"batch_s={batch_s} holds no sample at {fs_a} / {fs_f} Hz")
    batch_ns = int(round(batch_s * 1e9))
    rng = np.random.default_rng(seed)

    context = rclpy.Context()
    rclpy.init(context=context)
    tmp = tempfile.TemporaryDirectory(prefix="tactile_bench_")
    received: list[tuple[int, int]] = []  # (arrival ns, window end ns)
    lock = threading.Lock()
    stop = threading.Event()
    nodes = []
    procs: list[subprocess.Popen] = []
    window_params = {"robot": robot, "window.mode": "fixed", "window.length_s": float(length_s),
                     "window.hop_s": float(hop_s), "window.lateness_s": float(lateness_s)}
    model_path = str(Path(tmp.name) / "model.json")
    try:
        if in_process:
            nodes += [WindowNode(context=context, parameter_overrides=[
                          Parameter(k, value=v) for k, v in window_params.items()]),
                      ClassifierNode(context=context, parameter_overrides=[
                          Parameter("model_path", value=model_path)])]
        else:
            procs.append(_node_process("tactile_descriptors_ros.nodes.window_node", window_params))
            procs.append(_node_process("tactile_descriptors_ros.nodes.classifier_node", {"model_path": model_path}))
        probe = rclpy.create_node("tactile_bench_probe", context=context)
        nodes.append(probe)

        def on_prediction(msg) -> None:
            now = time.time_ns()
            with lock:
                received.append((now, stamp_to_ns(msg.window_end)))

        probe.create_subscription(Prediction, PREDICTION_TOPIC, on_prediction,
                                  QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
        from tactile_descriptors_msgs.msg import SkinCellFrame

        pubs, msgs = [], []
        offsets_a = (np.arange(n_a) * (1e9 / fs_a)).astype(np.int64)
        offsets_f = (np.arange(n_f) * (1e9 / fs_f)).astype(np.int64)
        for part in desc.body_parts:
            pub = probe.create_publisher(SkinCellFrame, FRAMES_TOPIC.format(body_part=part.name),
                                         QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
            for cell in part.cells:
                accel = np.clip(rng.normal(0, 12, (3, n_a)) + [[0], [0], [256]], -512, 511).astype(np.int16)
                force = rng.integers(300, 700, (3, n_f)).astype(np.uint16)
                frame = SkinFrame(0, accel, offsets_a, force, offsets_f, np.zeros(0, dtype=np.uint16))
                pubs.append(pub)
                msgs.append(skin_frame_to_msg(frame, cell_id=cell.id, body_part=part.name,
                                              force_n_per_count=n_per_count))
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        spinner = threading.Thread(target=lambda: _spin(executor, stop), daemon=True)
        spinner.start()
        deadline = time.monotonic() + discovery_timeout_s
        while time.monotonic() < deadline and not (
                all(p.get_subscription_count() > 0 for p in set(pubs))
                and probe.count_publishers(PREDICTION_TOPIC) > 0):
            time.sleep(0.1)
        if not all(p.get_subscription_count() > 0 for p in set(pubs)):
            raise RuntimeError("window_node did not subscribe to the frames within "
                               f"{discovery_timeout_s} s (see its log in $ROS_LOG_DIR)")
        time.sleep(0.5)

        start_ns = (time.time_ns() // batch_ns + 1) * batch_ns
        n_batches = int(round(duration_s / batch_s))
        published: list[tuple[int, int]] = []  # (first sample stamp of the batch, publish start ns)
        for k in range(n_batches):
            t0 = start_ns + k * batch_ns
            due = t0 + batch_ns  # every sample of the batch has been taken
            delay = (due - time.time_ns()) / 1e9
            if delay > 0:
                time.sleep(delay)
            sent = time.time_ns()
            stamp = ns_to_stamp(t0)
            for seq_pub, msg in zip(pubs, msgs):
                msg.header.stamp = stamp
                msg.sequence = k
                seq_pub.publish(msg)
            published.append((t0, sent))
        time.sleep(max(0.5, 2 * lateness_s + 2 * batch_s))
    finally:
        stop.set()
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
        for node in nodes:
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
        tmp.cleanup()

    t0s = np.array([p[0] for p in published], dtype=np.int64)
    sends = np.array([p[1] for p in published], dtype=np.int64)
    e2e, wait, proc = [], [], []
    for arrival, end in received:
        # the batch holding the first sample at or after end + lateness closes the window
        last_sample = t0s + (n_a - 1) * int(round(1e9 / fs_a))
        k = int(np.searchsorted(last_sample, end + int(round(lateness_s * 1e9)), side="left"))
        if k >= len(sends):
            continue
        e2e.append((arrival - end) / 1e6)
        wait.append((sends[k] - end) / 1e6)
        proc.append((arrival - sends[k]) / 1e6)
    lag = ((sends - (t0s + batch_ns)) / 1e6).tolist()
    return {
        "robot": robot, "cells": desc.n_cells, "batch_s": batch_s, "lateness_s": lateness_s,
        "nodes": "in process" if in_process else "separate processes",
        "window_s": length_s, "hop_s": hop_s, "duration_s": duration_s,
        "messages": len(published) * len(msgs), "predictions": len(received),
        "e2e": _summary(e2e), "wait": _summary(wait), "processing": _summary(proc),
        "publish_lag": _summary(lag),
        "publish_lag_last_ms": float(lag[-1]) if lag else None,
    }


def _spin(executor, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=0.05)
        except Exception:  # noqa: BLE001 - the context was shut down under us: stop spinning
            if stop.is_set():
                return
            raise


if __name__ == "__main__":  # pragma: no cover - manual run
    import json

    print(json.dumps(measure_latency(), indent=1, default=float))
