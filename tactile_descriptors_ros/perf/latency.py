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

Also reported: the CPU time each node process spent during the run (from
``/proc/<pid>/stat``) and per frame message for the window node(s), the
window node's fault counters and frames per callback (from its last
``/diagnostics``), the load average, whether the ``TARGET_MS`` median is
met, and (:func:`message_cost`) a micro benchmark of the window node's
per-message work outside the executor: deserialisation, message -> chunk
conversion, ``Windower.add`` / ``add_many``.  ``split_window_nodes=True``
starts one window node per body part (``tactile launch --split-window-nodes``,
:func:`~tactile_descriptors_ros.launching.graph.build_graph`).
Write-up: ``docs/latency.md``.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

__all__ = ["measure_latency", "message_cost", "TARGET_MS"]

#: Target: sensor stamp -> prediction, median, at NAO full rate.
TARGET_MS = 20.0


def _summary(values_ms: list[float]) -> dict:
    if not values_ms:
        return {"n": 0}
    arr = np.asarray(values_ms)
    return {"n": int(arr.size), "median_ms": float(np.median(arr)), "p95_ms": float(np.percentile(arr, 95)),
            "max_ms": float(arr.max())}


def _cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process so far (``/proc/<pid>/stat``; None where unavailable)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _probe_frames(desc, batch_s: float, seed: int) -> tuple[list, int, int, float]:
    """One ``SkinCellFrame`` per cell (part name, message), samples per batch and the accelerometer rate."""
    from ..nodes.conversions import SkinFrame, skin_frame_to_msg

    cell_type = next(iter(desc.cell_types.values()))
    fs_a, fs_f = cell_type.vibration.rate_hz, cell_type.deformation.rate_hz
    n_per_count = cell_type.force.n_per_count if cell_type.force else 0.002442
    n_a = int(round(batch_s * fs_a))
    n_f = int(round(batch_s * fs_f))
    if n_a < 1 or n_f < 1:
        raise ValueError(f"batch_s={batch_s} holds no sample at {fs_a} / {fs_f} Hz")
    rng = np.random.default_rng(seed)
    offsets_a = (np.arange(n_a) * (1e9 / fs_a)).astype(np.int64)
    offsets_f = (np.arange(n_f) * (1e9 / fs_f)).astype(np.int64)
    out = []
    for part in desc.body_parts:
        for cell in part.cells:
            accel = np.clip(rng.normal(0, 12, (3, n_a)) + [[0], [0], [256]], -512, 511).astype(np.int16)
            force = rng.integers(300, 700, (3, n_f)).astype(np.uint16)
            frame = SkinFrame(0, accel, offsets_a, force, offsets_f, np.zeros(0, dtype=np.uint16))
            out.append((part.name, skin_frame_to_msg(frame, cell_id=cell.id, body_part=part.name,
                                                     force_n_per_count=n_per_count)))
    return out, n_a, n_f, fs_a


def message_cost(*, robot: str = "nao", batch_s: float = 0.05, rounds: int = 40, repeat: int = 5,
                 seed: int = 0) -> dict:
    """Per-message CPU cost of the window node's work outside the executor, in microseconds.

    ``rounds`` batches of one ``SkinCellFrame`` per cell (fixed 2 s windows,
    0.5 s hop) go through CDR deserialisation (what rclpy does before the
    callback), :func:`~tactile_descriptors_ros.nodes.conversions.skin_msg_to_chunk`,
    and ``Windower.add`` one message at a time or ``Windower.add_many`` once
    per batch (what the window node does with the frames it takes in one
    callback), each followed by ``poll`` (window cutting included).  Minimum
    over ``repeat`` runs of the thread's CPU time (this machine is shared).
    """
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinCellFrame

    from ..core.robot import load_robot
    from ..core.windowing import Windower
    from ..nodes.conversions import ns_to_stamp, skin_msg_to_chunk

    desc = load_robot(robot)
    frames, _, _, _ = _probe_frames(desc, batch_s, seed)
    batch_ns = int(round(batch_s * 1e9))
    t0 = 1_000_000_000_000
    raws = []
    for k in range(rounds):
        round_raw = []
        for _, msg in frames:
            msg.header.stamp = ns_to_stamp(t0 + k * batch_ns)
            round_raw.append(serialize_message(msg))
        raws.append(round_raw)
    n = rounds * len(frames)
    best = {"deserialize": np.inf, "convert": np.inf, "add_poll": np.inf, "add_many_poll": np.inf}
    for _ in range(repeat):
        c = time.thread_time()
        msgs = [[deserialize_message(r, SkinCellFrame) for r in rr] for rr in raws]
        best["deserialize"] = min(best["deserialize"], time.thread_time() - c)
        c = time.thread_time()
        chunks = [[(int(m.cell_id), skin_msg_to_chunk(m)) for m in mm] for mm in msgs]
        best["convert"] = min(best["convert"], time.thread_time() - c)
        for key in ("add_poll", "add_many_poll"):
            w = Windower(desc, mode="fixed", length_s=2.0, hop_s=0.5, lateness_s=0.0)
            c = time.thread_time()
            for batch in chunks:
                if key == "add_poll":
                    for cid, chunk in batch:
                        w.add(cid, chunk)
                        w.poll()
                else:
                    w.add_many(batch)
                    w.poll()
            best[key] = min(best[key], time.thread_time() - c)
    per = {k: 1e6 * v / n for k, v in best.items()}
    return {"robot": robot, "cells": desc.n_cells, "batch_s": batch_s, "messages": n,
            "us_per_message": per,
            "us_per_message_batched": per["deserialize"] + per["convert"] + per["add_many_poll"],
            "note": "CPU time, minimum of the repeats; rclpy's executor adds its own cost per callback "
                    "(see window_cpu_us_per_message of the live run)"}


def measure_latency(*, duration_s: float = 8.0, batch_s: float = 0.05, lateness_s: float = 0.05,
                    length_s: float = 2.0, hop_s: float = 0.5, robot: str = "nao", seed: int = 0,
                    in_process: bool = False, discovery_timeout_s: float = 60.0,
                    split_window_nodes: bool = False, drain_max: int | None = None,
                    micro: bool = True) -> dict:
    """Publish ``duration_s`` of skin frames at full rate; time each Prediction (see the module doc).

    Parameters
    ----------
    duration_s, batch_s : float
        Seconds of data; sample time per ``SkinCellFrame`` (the skin driver's ``batch_s``).
    lateness_s, length_s, hop_s : float
        The window node's fixed windows (``window.*`` parameters).
    in_process : bool
        Run one window node and the classifier in the probe's process.
    split_window_nodes : bool
        One window node process per body part (the launcher's scale-out
        option); each publishes a pooled descriptor of its body part, so
        there is one prediction per body part and window.
    drain_max : int, optional
        The window node's ``frames.drain_max`` (default: the node's).
    micro : bool
        Also run :func:`message_cost` (before the graph starts).

    Returns
    -------
    dict
        JSON-able: settings, ``e2e``, ``wait``, ``processing`` and
        ``publish_lag`` summaries (median, p95, max in ms), ``complete``
        (window end -> last prediction of that window), message counts,
        ``target_ms`` / ``target_met``, per-process CPU, the window nodes'
        faults, the load average, and ``per_message`` (:func:`message_cost`).
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from diagnostic_msgs.msg import DiagnosticArray
    from tactile_descriptors_msgs.msg import Prediction, SkinCellFrame

    from ..core.robot import load_robot
    from ..launching.graph import build_graph
    from ..launching.processes import GraphProcesses
    from ..nodes.classifier_node import PREDICTION_TOPIC, ClassifierNode
    from ..nodes.conversions import ns_to_stamp, stamp_to_ns
    from ..nodes.window_node import FRAMES_TOPIC, WindowNode

    if in_process and split_window_nodes:
        raise ValueError("split_window_nodes starts one process per body part: not with in_process")
    desc = load_robot(robot)
    load_before = os.getloadavg()
    per_message = message_cost(robot=robot, batch_s=batch_s, seed=seed) if micro else None
    frames, n_a, _, fs_a = _probe_frames(desc, batch_s, seed)
    batch_ns = int(round(batch_s * 1e9))

    context = rclpy.Context()
    rclpy.init(context=context)
    tmp = tempfile.TemporaryDirectory(prefix="tactile_bench_")
    received: list[tuple[int, int]] = []  # (arrival ns, window end ns)
    diagnostics: dict[str, dict[str, str]] = {}
    diag_arrival = [0]  # monotonic ns of the last window node diagnostics
    lock = threading.Lock()
    stop = threading.Event()
    nodes = []
    graph: GraphProcesses | None = None
    window_params = {"window.mode": "fixed", "window.length_s": float(length_s),
                     "window.hop_s": float(hop_s), "window.lateness_s": float(lateness_s)}
    if drain_max is not None:
        window_params["frames.drain_max"] = int(drain_max)
    model_path = str(Path(tmp.name) / "model.json")
    cpu: dict[str, float | None] = {}
    try:
        if in_process:
            nodes += [WindowNode(context=context, parameter_overrides=[
                          Parameter(k, value=v) for k, v in {"robot": robot, **window_params}.items()]),
                      ClassifierNode(context=context, parameter_overrides=[
                          Parameter("model_path", value=model_path)])]
        else:
            specs = [dataclasses.replace(s, parameters={**s.parameters, **window_params})
                     if s.executable == "window_node" else s
                     for s in build_graph(desc, split_window_nodes=split_window_nodes, model_path=model_path)
                     if s.executable in ("window_node", "classifier_node")]
            graph = GraphProcesses(specs, output=None, workdir=tmp.name)
            graph.start()
        probe = rclpy.create_node("tactile_bench_probe", context=context)
        nodes.append(probe)

        def on_prediction(msg) -> None:
            now = time.time_ns()
            with lock:
                received.append((now, stamp_to_ns(msg.window_end)))

        def on_diagnostics(msg) -> None:
            for st in msg.status:
                values = {kv.key: kv.value for kv in st.values}
                if "descriptors_published" in values:
                    with lock:
                        diagnostics[st.name] = values
                        diag_arrival[0] = time.monotonic_ns()

        probe.create_subscription(Prediction, PREDICTION_TOPIC, on_prediction,
                                  QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
        probe.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics,
                                  QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
        pubs, msgs, by_part = [], [], {}
        for part in desc.body_parts:
            by_part[part.name] = probe.create_publisher(
                SkinCellFrame, FRAMES_TOPIC.format(body_part=part.name),
                QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
        for part_name, msg in frames:
            pubs.append(by_part[part_name])
            msgs.append(msg)
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
            tail = "; ".join(f"{n.spec.name}: {' | '.join(n.lines[-3:]) or 'no output'}"
                             for n in graph.nodes) if graph else ""
            raise RuntimeError(f"window_node did not subscribe to the frames within {discovery_timeout_s} s"
                               + (f" ({tail})" if tail else ""))
        time.sleep(0.5)

        pids = {n.spec.name: n.process.pid for n in graph.nodes} if graph else {"probe (all nodes)": os.getpid()}
        cpu_start = {name: _cpu_s(pid) for name, pid in pids.items()}
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
        done_ns = time.monotonic_ns()
        time.sleep(max(1.2, 2 * lateness_s + 2 * batch_s))  # the last predictions and one diagnostics period
        deadline = time.monotonic() + 5.0  # a loaded machine delays the diagnostics timer: wait for a fresh one
        while diag_arrival[0] < done_ns and time.monotonic() < deadline:
            time.sleep(0.05)
        for name, pid in pids.items():
            end = _cpu_s(pid)
            cpu[name] = None if end is None or cpu_start[name] is None else end - cpu_start[name]
    finally:
        stop.set()
        if graph is not None:
            graph.stop()
        for node in nodes:
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
        tmp.cleanup()

    t0s = np.array([p[0] for p in published], dtype=np.int64)
    sends = np.array([p[1] for p in published], dtype=np.int64)
    last_sample = t0s + (n_a - 1) * int(round(1e9 / fs_a))
    e2e, wait, proc = [], [], []
    complete: dict[int, int] = {}
    for arrival, end in received:
        # the batch holding the first sample at or after end + lateness closes the window
        k = int(np.searchsorted(last_sample, end + int(round(lateness_s * 1e9)), side="left"))
        if k >= len(sends):
            continue
        e2e.append((arrival - end) / 1e6)
        wait.append((sends[k] - end) / 1e6)
        proc.append((arrival - sends[k]) / 1e6)
        complete[end] = max(complete.get(end, 0), arrival)
    lag = ((sends - (t0s + batch_ns)) / 1e6).tolist()
    n_messages = len(published) * len(msgs)
    window_cpu = [v for k, v in cpu.items() if k.startswith("window_node") or k.startswith("probe")]
    window_cpu_s = float(sum(window_cpu)) if window_cpu and all(v is not None for v in window_cpu) else None
    faults: dict[str, int] = {}
    per_callback = []
    for values in diagnostics.values():
        for key, value in values.items():
            if key.startswith("fault_"):
                faults[key[6:]] = faults.get(key[6:], 0) + int(float(value))
        if "frames_per_callback" in values:
            per_callback.append(float(values["frames_per_callback"]))
    e2e_summary = _summary(e2e)
    return {
        "robot": robot, "cells": desc.n_cells, "batch_s": batch_s, "lateness_s": lateness_s,
        "nodes": "in process" if in_process else (
            "separate processes, one window node per body part" if split_window_nodes else "separate processes"),
        "settings": {"batch_s": batch_s, "lateness_s": lateness_s, "window_s": length_s, "hop_s": hop_s,
                     "duration_s": duration_s, "in_process": in_process,
                     "split_window_nodes": split_window_nodes, "drain_max": drain_max,
                     "messages_per_s": len(msgs) / batch_s},
        "window_s": length_s, "hop_s": hop_s, "duration_s": duration_s,
        "messages": n_messages, "predictions": len(received),
        "e2e": e2e_summary, "wait": _summary(wait), "processing": _summary(proc),
        "e2e_ms": [round(v, 2) for v in e2e],  # in arrival order: a slow start shows here
        "wait_ms": [round(v, 2) for v in wait], "processing_ms": [round(v, 2) for v in proc],
        "complete": _summary([(arr - end) / 1e6 for end, arr in complete.items()]),
        "publish_lag": _summary(lag),
        "publish_lag_last_ms": float(lag[-1]) if lag else None,
        "target_ms": TARGET_MS,
        "target_met": bool(e2e_summary.get("n") and e2e_summary["median_ms"] <= TARGET_MS),
        "cpu_s": cpu,
        "window_cpu_us_per_message": 1e6 * window_cpu_s / n_messages if window_cpu_s and n_messages else None,
        "window_cpu_fraction_of_core": window_cpu_s / (n_batches * batch_s) if window_cpu_s else None,
        "window_faults": faults,
        "frames_per_callback": float(np.mean(per_callback)) if per_callback else None,
        "per_message": per_message,
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
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
