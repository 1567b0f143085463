"""Sensor stamp -> Prediction latency through the ROS node graph (``tactile bench --latency``).

A probe node publishes ``SkinPartFrames`` messages for every body part of
the NAO at full rate (accelerometer 1 kHz, force 250 Hz, one message per
body part per ``batch_s`` of sample time holding all its cells, stamped with
the wall clock as a driver stamps its samples) into the real ``window_node`` and ``classifier_node`` (fixed
windows), and records when each ``Prediction`` arrives.  By default the two
nodes run as their own processes, as ``ros2 launch`` starts them
(``in_process=True`` runs them in the probe's process instead).  Reported
per prediction:

* ``e2e``: arrival time minus the window's end stamp (what a user waits
  after the last sample of a window was taken);
* ``wait``: the part of it spent waiting for data: a fixed window closes when
  a sample later than its end plus ``lateness_s`` arrives, i.e. when the
  batch holding that sample has been acquired and published (fixed windows
  end 1.5 sample periods before a batch ends,
  :data:`~tactile_descriptors_ros.core.windowing.GRID_MARGIN_PERIODS`, so
  without lateness that is the batch holding the window's last samples);
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
conversion, ``Windower.add_part`` (the node's path) beside ``add`` / ``add_many``.  ``split_window_nodes=True``
starts one window node per body part (``tactile launch --split-window-nodes``,
:func:`~tactile_descriptors_ros.launching.graph.build_graph`).
Write-up: ``lab/docs/performance.md, section Latency``.
"""

from __future__ import annotations

import dataclasses
import os
import random
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tactile_descriptors_ros.core.windowing import first_fixed_start, grid_margin_ns

__all__ = ["measure_latency", "message_cost", "node_message_cost", "contact_message_cost", "shipped_latency_settings",
           "ProbeFrames", "probe_frames", "set_sequence", "TARGET_MS", "DESIGN_WAIT_TARGET_MS", "EXPLORATION_RELEASED_S",
           "EXPLORATION_TOUCH_S"]

#: Target: sensor stamp (fixed: window end; exploration: release decision) -> prediction, p95, at NAO full rate.
TARGET_MS = 20.0
#: Target: the wait by design of the shipped NAO graph, from a window's end (or release decision) to the end of
#: the batch that closes it (:func:`_design_wait_ms`).
DESIGN_WAIT_TARGET_MS = 10.0


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


@dataclasses.dataclass
class ProbeFrames:
    """The probe's messages: ``templates[k % len(templates)]`` is batch ``k`` (one message per body part).

    Samples lie on the absolute grids of the nominal rates (a batch starting at
    a multiple of ``period_ns`` is template 0), so 250 Hz force in 10 ms
    batches is 3, 2, 3, 2 ... samples, as a driver cuts them.
    """

    templates: list[list[tuple[str, object]]]
    last_accel_offset_ns: np.ndarray  # per template: offset of its last accelerometer sample
    last_force_offset_ns: np.ndarray  # per template: offset of its last force sample
    period_ns: int


def probe_frames(desc, batch_s: float, seed: int, force_counts: tuple[int, int] = (300, 700),
                 phases_ns: dict[int, int] | None = None, whole_robot: bool = False) -> ProbeFrames:
    """The probe's ``SkinPartFrames`` for every body part (see :class:`ProbeFrames`).

    Force counts are drawn from ``force_counts`` (untared: 300-700 counts are
    0.7-1.7 N, every cell in contact; 0-20 counts are below the release threshold).
    ``phases_ns``: cell id -> how long after the grid that cell samples (less than
    an accelerometer period; cells on clocks of their own, :func:`cell_phases_ns`);
    every cell on the grid without it.  ``whole_robot``: each batch is one
    message of every body part's runs in order (body part ``""``), the same
    samples as the messages per body part.
    """
    import math

    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg
    from tactile_descriptors_ros.streams.frames import SkinFrame
    from tactile_descriptors_ros.streams.skin_parts import SkinRun, pack_skin_part

    cell_type = next(iter(desc.cell_types.values()))
    fs_a, fs_f = cell_type.vibration.rate_hz, cell_type.deformation.rate_hz
    n_per_count = cell_type.force.n_per_count if cell_type.force else 0.002442
    batch_ns = int(round(batch_s * 1e9))
    ta_ns, tf_ns = int(round(1e9 / fs_a)), int(round(1e9 / fs_f))
    if batch_ns < max(ta_ns, tf_ns):
        raise ValueError(f"batch_s={batch_s} is shorter than a sample period at {fs_a} / {fs_f} Hz")
    period_ns = math.lcm(batch_ns, ta_ns, tf_ns)
    rng = np.random.default_rng(seed)
    templates, last_a, last_f = [], [], []
    for j in range(period_ns // batch_ns):
        t0 = j * batch_ns
        offsets_a = np.arange(-(-t0 // ta_ns) * ta_ns, t0 + batch_ns, ta_ns, dtype=np.int64) - t0
        offsets_f = np.arange(-(-t0 // tf_ns) * tf_ns, t0 + batch_ns, tf_ns, dtype=np.int64) - t0
        out = []
        for part in desc.body_parts:
            runs = []
            for cell in part.cells:
                accel = np.clip(rng.normal(0, 12, (3, offsets_a.size)) + [[0], [0], [256]], -512, 511
                                ).astype(np.int16)
                force = rng.integers(force_counts[0], force_counts[1], (3, offsets_f.size)).astype(np.uint16)
                ph = (phases_ns or {}).get(cell.id, 0)
                frame = SkinFrame(0, accel, offsets_a - offsets_a[0] + ph, force, offsets_f - offsets_a[0] + ph,
                                  np.zeros(0, dtype=np.uint16))
                runs.append(SkinRun(cell.id, frame, np.zeros(3)))
            out.append((part.name, runs))
        if whole_robot:
            out = [("", [run for _, runs in out for run in runs])]
        templates.append([(name, skin_part_to_msg(pack_skin_part(name, runs, force_n_per_count=n_per_count)))
                          for name, runs in out])
        last_a.append(int(offsets_a[-1]))
        last_f.append(int(offsets_f[-1]) if offsets_f.size else -1)
    return ProbeFrames(templates, np.array(last_a, np.int64), np.array(last_f, np.int64), period_ns)


def cell_phases_ns(desc, seed: int) -> dict[int, int]:
    """Each cell's sampling instant after the grid, drawn over an accelerometer period (each body part's first
    cell on the grid: its message's stamp stays the batch's start), as cells on clocks of their own sample."""
    rng = np.random.default_rng(seed)
    out = {}
    for part in desc.body_parts:
        period_ns = int(round(1e9 / desc.cell_types[part.cell_type].vibration.rate_hz))
        for k, cell in enumerate(part.cells):
            out[cell.id] = int(rng.integers(0, period_ns)) if k else 0
    return out


def set_sequence(msg, k: int) -> None:
    """Every cell run of a probe message is batch ``k`` of its cell."""
    import array

    msg.sequence = array.array("I", [k & 0xFFFFFFFF]) * len(msg.cell_ids)


def shipped_latency_settings(robot: str = "nao") -> tuple[float, float]:
    """The skin driver's ``batch_s`` and the window node's ``window.lateness_s`` of a robot's shipped graph."""
    from tactile_descriptors_ros.launching.graph import build_graph

    specs = build_graph(robot)
    driver = next(s for s in specs if s.executable == "skin_driver")
    window = next(s for s in specs if s.executable == "window_node")
    return float(driver.parameters.get("batch_s", 0.05)), float(window.parameters.get("window.lateness_s", 0.05))


#: Touch schedule of the exploration run: released, then touching, per cycle [s].
EXPLORATION_RELEASED_S = 0.4
EXPLORATION_TOUCH_S = 1.2


def _serialized_rounds(desc, batch_s: float, seed: int, rounds: int, start_ns: int,
                       in_order: bool = False) -> list[list[bytes]]:
    """``rounds`` batches of the probe's ``SkinPartFrames`` (one per body part), CDR-serialised, stamped
    ``batch_s`` apart from about ``start_ns`` (a whole number of sample periods); ``in_order``: each cell's
    batch numbers count the rounds (:func:`set_sequence`)."""
    from rclpy.serialization import serialize_message

    from tactile_descriptors_ros.nodes.conversions import ns_to_stamp

    probe = probe_frames(desc, batch_s, seed)
    batch_ns = int(round(batch_s * 1e9))
    t0 = probe.period_ns * (start_ns // probe.period_ns)
    out = []
    for k in range(rounds):
        batch = []
        for _, msg in probe.templates[k % len(probe.templates)]:
            msg.header.stamp = ns_to_stamp(t0 + k * batch_ns)
            if in_order:
                set_sequence(msg, k)
            batch.append(serialize_message(msg))
        out.append(batch)
    return out


def message_cost(*, robot: str = "nao", batch_s: float = 0.05, rounds: int = 40, repeat: int = 5,
                 seed: int = 0, mode: str = "fixed") -> dict:
    """Per-message CPU cost of the window node's work outside the executor, in microseconds.

    ``rounds`` batches of one ``SkinPartFrames`` per body part (``mode``:
    fixed 2 s windows, 0.5 s hop, or explorations, every cell touching) go through CDR deserialisation (what rclpy does
    before the callback), then two paths, each followed by one ``poll`` per
    batch (window cutting included):

    * the window node's: each message in one piece,
      :func:`~tactile_descriptors_ros.nodes.conversions.skin_part_msg_to_part_chunk`
      (``convert_part``) and ``Windower.add_part`` (``add_part_poll``);
    * per cell, for comparison:
      :func:`~tactile_descriptors_ros.nodes.conversions.skin_part_msg_to_chunks`
      (``convert``) and ``Windower.add`` one cell chunk at a time
      (``add_poll``) or ``Windower.add_many`` once per batch (``add_many_poll``).

    ``us_per_message_batched`` is the node's path (deserialise +
    ``convert_part`` + ``add_part_poll``), ``us_per_message_per_cell`` the
    best per-cell one.  Minimum over ``repeat`` runs of the thread's CPU time
    (this machine is shared).
    """
    from rclpy.serialization import deserialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.core.windowing import Windower
    from tactile_descriptors_ros.nodes.conversions import (
        skin_part_msg_to_chunks,
        skin_part_msg_to_part_chunk,
    )

    desc = load_robot(robot)
    raws = _serialized_rounds(desc, batch_s, seed, rounds, 1_000_000_000_000)
    n = rounds * len(desc.body_parts)
    keys = ("deserialize", "convert_part", "add_part_poll", "convert", "add_poll", "add_many_poll")
    best = dict.fromkeys(keys, np.inf)
    windows: dict[str, int] = {}
    for _ in range(repeat):
        c = time.thread_time()
        msgs = [[deserialize_message(r, SkinPartFrames) for r in rr] for rr in raws]
        best["deserialize"] = min(best["deserialize"], time.thread_time() - c)
        c = time.thread_time()
        parts = [[skin_part_msg_to_part_chunk(m) for m in mm] for mm in msgs]
        best["convert_part"] = min(best["convert_part"], time.thread_time() - c)
        c = time.thread_time()
        chunks = [[item for m in mm for item in skin_part_msg_to_chunks(m)] for mm in msgs]
        best["convert"] = min(best["convert"], time.thread_time() - c)
        for key in ("add_part_poll", "add_poll", "add_many_poll"):
            w = Windower(desc, mode=mode, length_s=2.0, hop_s=0.5, lateness_s=0.0)
            cut = 0
            c = time.thread_time()
            for batch, part_batch in zip(chunks, parts):
                if key == "add_part_poll":
                    for part in part_batch:
                        w.add_part(part)
                    cut += len(w.poll())
                elif key == "add_poll":
                    for cid, chunk in batch:
                        w.add(cid, chunk)
                        cut += len(w.poll())
                else:
                    w.add_many(batch)
                    cut += len(w.poll())
            best[key] = min(best[key], time.thread_time() - c)
            windows[key] = cut
    per = {k: 1e6 * v / n for k, v in best.items()}
    return {"robot": robot, "cells": desc.n_cells, "batch_s": batch_s, "mode": mode, "messages": n,
            "us_per_message": per, "windows_cut": windows,
            "us_per_message_batched": per["deserialize"] + per["convert_part"] + per["add_part_poll"],
            "us_per_message_per_cell": per["deserialize"] + per["convert"] + min(per["add_poll"],
                                                                                per["add_many_poll"]),
            "note": "CPU time, minimum of the repeats; rclpy's executor adds its own cost per callback "
                    "(see window_cpu_us_per_message of the live run)"}


#: How :func:`node_message_cost` and :func:`contact_message_cost` hand the node its messages: deserialised
#: before the timing (the callback's own cost), the CDR bytes deserialised by rclpy inside it, or the bytes
#: themselves (a serialised subscription's: the node reads them, ``frames.serialized``).
TAKEN = ("message", "rclpy", "bytes")


def _callback_cost(make_node, robot: str, batch_s: float, rounds: int, warm_rounds: int, seed: int,
                   taken: str = "message") -> tuple[float, int, dict[str, int], tuple[int, int]]:
    """A node made by ``make_node(context)`` takes ``rounds`` batches of the probe's ``SkinPartFrames`` (one per
    body part, stamps ``batch_s`` apart, each cell's batch numbers in order, every cell touching) through its
    ``_on_frames``, one message a call, in this process, without an executor; the CPU of those after the first
    ``warm_rounds``, how many they were, the node's faults and its ``contacts_published`` and
    ``contacts_unsubscribed`` (0 for a node without).  ``taken`` (:data:`TAKEN`): the messages deserialised
    from CDR as rclpy gives them before the timing, the CDR deserialised by rclpy in it, or the CDR bytes
    handed to the callback."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # a node of its own: discovery stays on this machine
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    import rclpy
    from rclpy.serialization import deserialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.core.robot import load_robot

    if not 0 <= warm_rounds < rounds:
        raise ValueError(f"warm_rounds must be in [0, rounds), got {warm_rounds} of {rounds}")
    if taken not in TAKEN:
        raise ValueError(f"taken must be one of {TAKEN}, got {taken!r}")
    desc = load_robot(robot)
    msgs = [raw for batch in _serialized_rounds(desc, batch_s, seed, rounds, 1_800_000_000_000_000_000, in_order=True)
            for raw in batch]
    if taken == "message":
        msgs = [deserialize_message(raw, SkinPartFrames) for raw in msgs]
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = make_node(context)
        try:
            n_warm = warm_rounds * len(desc.body_parts)
            deserialize = taken == "rclpy"
            for msg in msgs[:n_warm]:
                node._on_frames(deserialize_message(msg, SkinPartFrames) if deserialize else msg)
            started = time.thread_time()
            for msg in msgs[n_warm:]:
                node._on_frames(deserialize_message(msg, SkinPartFrames) if deserialize else msg)
            cpu_s = time.thread_time() - started
            faults = {k: int(v) for k, v in node.faults.items()}
            contacts = (int(getattr(node, "contacts_published", 0)), int(getattr(node, "contacts_unsubscribed", 0)))
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return cpu_s, len(msgs) - n_warm, faults, contacts


def node_message_cost(*, robot: str = "nao", mode: str = "exploration", batch_s: float = 0.01, rounds: int = 1200,
                      warm_rounds: int = 100, seed: int = 0, taken: str = "message") -> dict:
    """CPU per message of the window node's own frames callback, called in this process without an executor.

    A :class:`~tactile_descriptors_ros.nodes.window_node.WindowNode` (``robot``,
    ``window.mode`` = ``mode``) takes ``rounds`` batches of the probe's
    ``SkinPartFrames`` (one per body part, deserialised from CDR as rclpy gives
    them, stamps ``batch_s`` apart, each cell's batch numbers in order, every
    cell touching) through ``_on_frames``, one message and one poll a call:
    conversion, the runs' checks, the windower's intake and poll, the node's
    bookkeeping; not rclpy's executor, nor the deserialisation unless
    ``taken`` says (:data:`TAKEN`: ``rclpy`` times rclpy's deserialisation
    with the callback, ``bytes`` hands the callback the CDR bytes, which the
    node reads).  The first ``warm_rounds`` are not timed.  ``faults`` are the node's counters after
    the run (the probe loses nothing: every one is 0 unless something is
    wrong).  A thread's CPU time, so a shared machine slows it less than a
    wall clock.
    """
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.window_node import WindowNode

    cpu_s, timed, faults, _ = _callback_cost(
        lambda context: WindowNode(context=context, parameter_overrides=[
            Parameter("robot", value=robot), Parameter("window.mode", value=mode)]),
        robot, batch_s, rounds, warm_rounds, seed, taken)
    return {"robot": robot, "mode": mode, "batch_s": batch_s, "taken": taken, "messages_timed": timed,
            "us_per_message": 1e6 * cpu_s / timed, "faults": faults}


def contact_message_cost(*, robot: str = "nao", batch_s: float = 0.01, rounds: int = 1200, warm_rounds: int = 100,
                         seed: int = 0, compiled: bool = True, lazy: bool = False, taken: str = "message") -> dict:
    """CPU per message of the contact node's own frames callback, called in this process without an executor.

    A :class:`~tactile_descriptors_ros.nodes.contact_node.ContactNode` of
    ``robot`` takes the probe's messages as :func:`node_message_cost` gives
    them to the window node: each body part's message reduced, its contact
    located, its ``Contact`` and ``WrenchStamped`` built and published (no
    subscriber: ``contact.lazy`` is false unless ``lazy``), the display's
    bookkeeping and its ticks at 10 Hz of wall time; not rclpy's executor, nor
    the deserialisation unless ``taken`` says (as there).  ``lazy`` True runs the node as shipped with nobody
    subscribed to its contacts: each is counted, not located nor published.
    ``compiled`` False sums the messages' runs with numpy
    (:data:`~tactile_descriptors_ros.core.contact.COMPILED_SUMS`) for a
    comparison in one session.  ``contacts_published`` and
    ``contacts_unsubscribed`` count every message's contact, warm-up included;
    ``faults`` are the node's counters after the run.
    """
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.core import contact
    from tactile_descriptors_ros.nodes.contact_node import ContactNode

    before = contact.COMPILED_SUMS
    contact.COMPILED_SUMS = compiled
    try:
        cpu_s, timed, faults, (contacts, unsubscribed) = _callback_cost(
            lambda context: ContactNode(context=context, parameter_overrides=[
                Parameter("robot", value=robot), Parameter("contact.lazy", value=lazy)]),
            robot, batch_s, rounds, warm_rounds, seed, taken)
    finally:
        contact.COMPILED_SUMS = before
    return {"robot": robot, "batch_s": batch_s, "compiled": compiled, "lazy": lazy, "taken": taken,
            "messages_timed": timed,
            "us_per_message": 1e6 * cpu_s / timed, "contacts_published": contacts,
            "contacts_unsubscribed": unsubscribed, "faults": faults}


def measure_latency(*, duration_s: float = 8.0, batch_s: float | None = None, lateness_s: float | None = None,
                    mode: str = "fixed", length_s: float = 2.0, hop_s: float = 0.5, robot: str = "nao",
                    seed: int = 0, in_process: bool = False, discovery_timeout_s: float = 60.0,
                    split_window_nodes: bool = False, drain_max: int | None = None,
                    groups: Sequence[str] | None = None, window_parameters: dict | None = None,
                    micro: bool = True, cell_phases: bool = False) -> dict:
    """Publish ``duration_s`` of skin frames at full rate; time each Prediction (see the module doc).

    Parameters
    ----------
    duration_s : float
        Seconds of data.
    batch_s, lateness_s : float, optional
        Sample time per ``SkinPartFrames`` (the skin driver's ``batch_s``) and
        the window node's ``window.lateness_s``; default: the robot's shipped
        graph (:func:`shipped_latency_settings`).
    mode : {"fixed", "exploration"}
        ``fixed``: every cell in contact, fixed windows of ``length_s`` every
        ``hop_s``, timed from the window's end stamp.  ``exploration``: every
        cell touches for :data:`EXPLORATION_TOUCH_S` and lets go for
        :data:`EXPLORATION_RELEASED_S` in turn; each exploration is timed from
        its release decision (window end + ``release_s``: the first sample
        time at which the release is known).
    length_s, hop_s : float
        The fixed windows.
    in_process : bool
        Run one window node and the classifier in the probe's process.
    split_window_nodes : bool
        One window node process per body part (the launcher's scale-out
        option); each publishes a pooled descriptor of its body part, so
        there is one prediction per body part and window.
    drain_max : int, optional
        The window node's ``frames.drain_max`` (default: the node's).
    groups : sequence of str, optional
        The window node's ``descriptor.groups`` (default: the robot's shipped
        feature groups); ``["paper"]`` times the graph with the paper's
        descriptor.
    window_parameters : dict, optional
        More window node parameters (e.g. ``{"qos.frames.reliability": "reliable"}``).
    micro : bool
        Also run :func:`message_cost` (before the graph starts).
    cell_phases : bool
        Every cell samples at its own instants (:func:`cell_phases_ns`), as
        cells on clocks of their own do, instead of all on one grid.

    Returns
    -------
    dict
        JSON-able: settings, ``e2e``, ``wait``, ``processing`` and
        ``publish_lag`` summaries (median, p95, max in ms), ``complete``
        (reference -> last prediction of that window), ``parts_ms`` (what each
        part of ``e2e`` costs: design wait, frames age when the window node
        takes them, window node, describing, classifier), message counts,
        ``design_wait_ms``, ``target_ms`` / ``target_met`` (p95), per-process
        CPU, the window nodes' faults, the load average, and ``per_message``
        (:func:`message_cost`).
    """
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, Prediction, SkinPartFrames
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.launching.processes import GraphProcesses
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode
    from tactile_descriptors_ros.nodes.common import executor_kind
    from tactile_descriptors_ros.nodes.conversions import ns_to_stamp, stamp_to_ns
    from tactile_descriptors_ros.nodes.window_node import WindowNode, frames_matched
    from tactile_descriptors_ros.topics import DESCRIPTOR_TOPIC, FRAMES_TOPIC, PREDICTION_TOPIC

    if in_process and split_window_nodes:
        raise ValueError("split_window_nodes starts one process per body part: not with in_process")
    if mode not in ("fixed", "exploration"):
        raise ValueError(f"mode must be fixed or exploration, not {mode!r}")
    shipped_batch_s, shipped_lateness_s = shipped_latency_settings(robot)
    batch_s = shipped_batch_s if batch_s is None else float(batch_s)
    lateness_s = shipped_lateness_s if lateness_s is None else float(lateness_s)
    desc = load_robot(robot)
    release_ns = int(round(desc.window.release_s * 1e9))
    load_before = os.getloadavg()
    per_message = message_cost(robot=robot, batch_s=batch_s, seed=seed, mode=mode) if micro else None
    own = cell_phases_ns(desc, seed) if cell_phases else None
    if mode == "fixed":
        phases = {"contact": probe_frames(desc, batch_s, seed, phases_ns=own)}
    else:
        phases = {"contact": probe_frames(desc, batch_s, seed, (800, 1000), own),
                  "released": probe_frames(desc, batch_s, seed + 1, (0, 20), own)}
    contact_frames = phases["contact"]
    n_templates = len(contact_frames.templates)
    batch_ns = int(round(batch_s * 1e9))

    context = rclpy.Context()
    rclpy.init(context=context)
    tmp = tempfile.TemporaryDirectory(prefix="tactile_bench_")
    received: list[tuple[int, int]] = []  # (arrival ns, window end ns)
    descriptors: dict[int, list[int]] = {}  # window end ns -> arrival ns of its descriptors
    diagnostics: dict[str, dict[str, str]] = {}
    diag_arrival = [0]  # monotonic ns of the last window node diagnostics
    lock = threading.Lock()
    stop = threading.Event()
    nodes = []
    graph: GraphProcesses | None = None
    window_params = {"window.mode": mode, "window.length_s": float(length_s),
                     "window.hop_s": float(hop_s), "window.lateness_s": float(lateness_s)}
    if drain_max is not None:
        window_params["frames.drain_max"] = int(drain_max)
    if groups is not None:
        window_params["descriptor.groups"] = [str(g) for g in groups]
    window_params.update(window_parameters or {})
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

        def on_descriptor(msg) -> None:
            now = time.time_ns()
            with lock:
                descriptors.setdefault(stamp_to_ns(msg.window_end), []).append(now)

        def on_diagnostics(msg) -> None:
            for st in msg.status:
                values = {kv.key: kv.value for kv in st.values}
                if "descriptors_published" in values:
                    with lock:
                        diagnostics[st.name] = values
                        diag_arrival[0] = time.monotonic_ns()

        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        probe.create_subscription(Prediction, PREDICTION_TOPIC, on_prediction, reliable)
        probe.create_subscription(Descriptor, DESCRIPTOR_TOPIC, on_descriptor, reliable)
        probe.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, reliable)
        by_part = {part.name: probe.create_publisher(SkinPartFrames, FRAMES_TOPIC.format(body_part=part.name),
                                                     QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
                   for part in desc.body_parts}
        pubs = list(by_part.values())
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        spinner = threading.Thread(target=lambda: _spin(executor, stop), daemon=True)
        spinner.start()

        def frames_ready() -> bool:
            """Both sides of every frames topic matched: discovery matches each side on its own, and a
            best-effort subscription drops what a publisher it does not know yet sends.  The probe's writers
            count the window nodes' subscriptions; the window nodes' diagnostics count the probe."""
            with lock:
                reports = list(diagnostics.values())
            return (all(p.get_subscription_count() > 0 for p in pubs)
                    and all(any(frames_matched(r, part) for r in reports) for part in by_part))

        deadline = time.monotonic() + discovery_timeout_s
        while time.monotonic() < deadline and not (frames_ready() and probe.count_publishers(PREDICTION_TOPIC) > 0):
            time.sleep(0.1)
        if not frames_ready():
            tail = "; ".join(f"{n.spec.name}: {' | '.join(n.lines[-3:]) or 'no output'}"
                             for n in graph.nodes) if graph else ""
            raise RuntimeError(f"window_node did not subscribe to the frames within {discovery_timeout_s} s"
                               + (f" ({tail})" if tail else ""))

        pids = {n.spec.name: n.process.pid for n in graph.nodes} if graph else {"probe (all nodes)": os.getpid()}
        cpu_start = {name: _cpu_s(pid) for name, pid in pids.items()}
        start_ns = (time.time_ns() // contact_frames.period_ns + 1) * contact_frames.period_ns  # template 0 first
        n_batches = int(round(duration_s / batch_s))
        cycle_ns = int(round((EXPLORATION_RELEASED_S + EXPLORATION_TOUCH_S) * 1e9))
        released_ns = int(round(EXPLORATION_RELEASED_S * 1e9))
        published: list[tuple[int, int]] = []  # (first sample stamp of the batch, publish start ns)
        for k in range(n_batches):
            t0 = start_ns + k * batch_ns
            due = t0 + batch_ns  # every sample of the batch has been taken
            delay = (due - time.time_ns()) / 1e9
            if delay > 0:
                time.sleep(delay)
            touching = mode == "fixed" or (k * batch_ns) % cycle_ns >= released_ns
            sent = time.time_ns()
            stamp = ns_to_stamp(t0)
            for pub, (_, msg) in zip(pubs, phases["contact" if touching else "released"].templates[k % n_templates]):
                msg.header.stamp = stamp
                set_sequence(msg, k)
                pub.publish(msg)
            published.append((t0, sent))
        done_ns = time.monotonic_ns()
        # the last predictions: until every window the data closed has its prediction (a node behind its input
        # answers late), or nothing came for 10 s; then one diagnostics period
        expected = _expected_predictions(mode, start_ns, n_batches * batch_ns, length_s, hop_s, lateness_s,
                                         release_ns, grid_margin_ns(desc)) * (len(desc.body_parts) if split_window_nodes else 1)
        time.sleep(max(1.2, 2 * lateness_s + 2 * batch_s))
        deadline = time.monotonic() + 60.0
        last_count, quiet_since = -1, time.monotonic()
        while time.monotonic() < deadline:
            with lock:
                count = len(received)
            if count >= expected:
                break
            if count != last_count:
                last_count, quiet_since = count, time.monotonic()
            elif time.monotonic() - quiet_since > 10.0:
                break
            time.sleep(0.05)
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
    which = np.arange(len(t0s)) % n_templates
    if mode == "fixed":
        # a fixed window closes once every cell has a vibration sample at or after end + lateness
        closing_sample = t0s + contact_frames.last_accel_offset_ns[which]
        delay_ns = int(round(lateness_s * 1e9))
        reference_delay_ns = 0
    else:
        # an exploration ends once every cell's force stayed below release for release_s
        last_f = contact_frames.last_force_offset_ns[which]
        closing_sample = np.maximum.accumulate(np.where(last_f >= 0, t0s + last_f, 0))
        delay_ns = release_ns
        reference_delay_ns = release_ns
    e2e, wait, proc, window_stage, classifier_stage = [], [], [], [], []
    complete: dict[int, int] = {}
    for arrival, end in received:
        ref = end + reference_delay_ns
        k = int(np.searchsorted(closing_sample, end + delay_ns, side="left"))
        if k >= len(sends):
            continue
        e2e.append((arrival - ref) / 1e6)
        wait.append((sends[k] - ref) / 1e6)
        proc.append((arrival - sends[k]) / 1e6)
        before = [t for t in descriptors.get(end, []) if t <= arrival]
        if before:
            window_stage.append((max(before) - sends[k]) / 1e6)
            classifier_stage.append((arrival - max(before)) / 1e6)
        complete[ref] = max(complete.get(ref, 0), arrival)
    lag = ((sends - (t0s + batch_ns)) / 1e6).tolist()
    n_messages = len(published) * len(pubs)
    window_cpu = [v for k, v in cpu.items() if k.startswith("window_node") or k.startswith("probe")]
    window_cpu_s = float(sum(window_cpu)) if window_cpu and all(v is not None for v in window_cpu) else None
    faults: dict[str, int] = {}
    per_callback = []
    node_timing: dict[str, dict[str, float]] = {}
    ahead: dict[str, int] = {}
    heads: dict[str, int] = {}
    for name, values in diagnostics.items():
        for key, value in values.items():
            if key.startswith("fault_"):
                faults[key[6:]] = faults.get(key[6:], 0) + int(float(value))
            elif key.startswith("described_ahead_"):
                ahead[key[16:]] = ahead.get(key[16:], 0) + int(float(value))
            elif key in ("cut_ahead_used", "cut_ahead_recut"):
                heads[key[10:]] = heads.get(key[10:], 0) + int(float(value))
        if "frames_per_callback" in values:
            per_callback.append(float(values["frames_per_callback"]))
        node_timing[name] = {k: float(v) for k, v in values.items() if k.startswith(("describe_", "cut_", "frames_age_"))}
    e2e_summary = _summary(e2e)
    design_wait_ms = _design_wait_ms(mode, start_ns, n_batches * batch_ns, batch_ns, length_s, hop_s, lateness_s,
                                     grid_margin_ns(desc))
    return {
        "robot": robot, "cells": desc.n_cells, "batch_s": batch_s, "lateness_s": lateness_s, "mode": mode,
        "reference": "window end stamp" if mode == "fixed" else
                     f"release decision (window end + release_s = {release_ns / 1e6:g} ms)",
        "nodes": "in process" if in_process else (
            "separate processes, one window node per body part" if split_window_nodes else "separate processes"),
        "settings": {"batch_s": batch_s, "lateness_s": lateness_s, "window_mode": mode, "window_s": length_s,
                     "hop_s": hop_s, "release_s": release_ns / 1e9, "duration_s": duration_s,
                     "in_process": in_process, "split_window_nodes": split_window_nodes, "drain_max": drain_max,
                     "cell_phases": cell_phases,
                     "groups": list(groups) if groups is not None else list(desc.descriptor.groups),
                     "messages_per_s": len(pubs) / batch_s,
                     "executor": "the bench's own" if in_process else executor_kind()},
        "window_s": length_s, "hop_s": hop_s, "duration_s": duration_s,
        "messages": n_messages, "predictions": len(received), "expected_predictions": expected,
        "e2e": e2e_summary, "wait": _summary(wait), "processing": _summary(proc),
        "e2e_ms": [round(v, 2) for v in e2e],  # in arrival order: a slow start shows here
        "wait_ms": [round(v, 2) for v in wait], "processing_ms": [round(v, 2) for v in proc],
        # the same predictions' window node and classifier stages (those whose descriptor the probe saw)
        "window_node_ms": [round(v, 2) for v in window_stage], "classifier_ms": [round(v, 2) for v in classifier_stage],
        # each window node's rehearsal of its describing path at its first frames (nodes/window_node.py)
        "rehearsal_ms": {name: float(values["rehearsal_ms"]) for name, values in diagnostics.items()
                         if "rehearsal_ms" in values},
        "parts_ms": {
            "design_wait": _summary(wait),
            "frames_age_at_window_node": _node_summary(node_timing, "frames_age"),
            "window_node": _summary(window_stage),
            "cut": _node_summary(node_timing, "cut"),
            "describe": _node_summary(node_timing, "describe"),
            # explorations: described during the release time, off the path after the decision (core/ahead.py)
            "describe_ahead": _node_summary(node_timing, "describe_ahead"),
            # fixed windows: their samples cut before they close, off the path after the closing batch
            "cut_ahead": _node_summary(node_timing, "cut_ahead"),
            "classifier": _summary(classifier_stage),
        },
        "complete": _summary([(arr - ref) / 1e6 for ref, arr in complete.items()]),
        "publish_lag": _summary(lag),
        "publish_lag_last_ms": float(lag[-1]) if lag else None,
        "design_wait_ms": design_wait_ms,
        "design_wait_target_ms": DESIGN_WAIT_TARGET_MS,
        "target_ms": TARGET_MS,
        "target_met": bool(e2e_summary.get("n") and e2e_summary["p95_ms"] <= TARGET_MS),
        "cpu_s": cpu,
        "window_cpu_us_per_message": 1e6 * window_cpu_s / n_messages if window_cpu_s and n_messages else None,
        "window_cpu_fraction_of_core": window_cpu_s / (n_batches * batch_s) if window_cpu_s else None,
        "window_faults": faults,
        # windows described ahead: used (published at the decision), changed (described again), discarded
        "described_ahead": ahead,
        # fixed windows closed from the samples cut ahead (used) or cut whole although some were (recut)
        "cut_ahead": heads,
        "frames_per_callback": float(np.mean(per_callback)) if per_callback else None,
        "per_message": per_message,
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
    }


def _fixed_ends(start_ns: int, span_ns: int, length_s: float, hop_s: float, lateness_s: float,
                margin_ns: int) -> np.ndarray:
    """Ends of the fixed windows the probe's data close: on the windower's grid
    (:func:`~tactile_descriptors_ros.core.windowing.first_fixed_start`), each once an accelerometer sample at or
    after its end + lateness was sent (the last one is 1 ms before the data's end)."""
    length_ns, hop_ns = int(round(length_s * 1e9)), int(round(hop_s * 1e9))
    first_end = first_fixed_start(start_ns, length_ns, hop_ns, margin_ns) + length_ns
    last_closing = start_ns + span_ns - 1_000_000 - int(round(lateness_s * 1e9))
    return np.arange(first_end, last_closing + 1, hop_ns, dtype=np.int64)


def _design_wait_ms(mode: str, start_ns: int, span_ns: int, batch_ns: int, length_s: float, hop_s: float,
                    lateness_s: float, margin_ns: int) -> float:
    """The wait by design, from a window's end stamp (exploration: release decision) to the end of the batch
    that closes it: for fixed windows, the batch holding end + lateness (the longest over the run's windows);
    for explorations, a whole batch (the sample that decides a release can be the first of a batch)."""
    if mode != "fixed":
        return batch_ns / 1e6
    ends = _fixed_ends(start_ns, span_ns, length_s, hop_s, lateness_s, margin_ns)
    if not ends.size:
        return batch_ns / 1e6 + lateness_s * 1e3
    late = ends + int(round(lateness_s * 1e9))
    return float(np.max((late // batch_ns + 1) * batch_ns - ends)) / 1e6


def _expected_predictions(mode: str, start_ns: int, span_ns: int, length_s: float, hop_s: float,
                          lateness_s: float, release_ns: int, margin_ns: int) -> int:
    """Windows the probe's data close (one prediction each with one window node)."""
    if mode == "fixed":
        return int(_fixed_ends(start_ns, span_ns, length_s, hop_s, lateness_s, margin_ns).size)
    cycle_ns = int(round((EXPLORATION_RELEASED_S + EXPLORATION_TOUCH_S) * 1e9))
    first_end = int(round((EXPLORATION_RELEASED_S + EXPLORATION_TOUCH_S) * 1e9))
    usable = span_ns - first_end - release_ns - 50_000_000  # the release shows after release_s (and smoothing)
    return max(0, usable // cycle_ns + 1) if usable >= 0 else 0


def _node_summary(node_timing: dict[str, dict[str, float]], prefix: str) -> dict:
    """A window node timing (``<prefix>_ms_p50`` / ``_p95`` / ``_max`` in its diagnostics); the worst over nodes."""
    rows = [t for t in node_timing.values() if f"{prefix}_ms_p50" in t]
    if not rows:
        return {"n": 0}
    return {"n": int(sum(t.get(f"{prefix}_n", 0) for t in rows)),
            "median_ms": max(t[f"{prefix}_ms_p50"] for t in rows), "p95_ms": max(t[f"{prefix}_ms_p95"] for t in rows),
            "max_ms": max(t[f"{prefix}_ms_max"] for t in rows), "source": "window node diagnostics"}


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
