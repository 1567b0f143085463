"""Soak test of a robot's node graph at full rate (``tactile bench --soak SECONDS``).

The robot's graph (``nodes:`` of its description: drivers on the simulated
transport, window node(s), classifier) runs as separate processes, as
``tactile launch`` starts it, for a given time at the sensors' real rate
(``sim.speed`` 1; device stamps, as in the demo).  The scene is the robot's demo scene played over
and over, whole, until it lasts the whole soak (every cycle touches what the
demo touches, in the demo's order: the NAO's right-hand slides, then large
objects against every cell), and without the simulated frame drops and
corruptions, so every lost frame the report shows was lost by the graph
itself.

Every ``sample_s`` the soak samples each node's resident memory (RSS) and
CPU time (psutil, by PID) and keeps the newest ``/diagnostics`` of every node.
The report gives per node RSS over time (and at every whole minute), mean
CPU, the RSS growth after the warm-up (the first minute or the scene's first
cycle, whichever is longer: by then every kind of touch has been through the
graph once; the goal: at most 5 % over 10 minutes), the window node's sample
buffers, and the frames in three parts:

* **never sent**: the frames real sensors would have sent while the driver
  ran (the scene's frame rate times that time) that the simulated bus did
  not put out, because the simulator, on the same loaded machine, fell
  behind real time.  The paced simulator drops nothing: what it did not send
  in time is simply not part of the soak.  The share of the real rate it
  sent says whether the machine kept up;
* **lost on the bus**: sequence gaps the driver found between the frames
  the bus delivered (the soak's scene injects none);
* **sent and lost**: messages the driver published that the window node
  never received (gaps in the messages' sequence numbers, counted when a
  later message arrives; for a body part's ``SkinPartFrames``, gaps in each
  cell's batch numbers, so a message dropped on the way is all its cells'
  batches): the graph's own loss, in messages or cell batches and in frames.

Late frames (out of order, duplicates, clock jumps, windows with gaps) are
counted apart, and the load of the machine is part of the result: on a
shared machine lost frames are a fact about the machine as much as about the
graph.
"""

from __future__ import annotations

import math
import os
import random
import sys
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

__all__ = ["NodeSamples", "SoakReport", "soak_scene", "scene_frames_per_s", "run_soak", "format_soak",
           "GROWTH_GOAL_PERCENT", "KEEPS_UP_FRACTION", "WARMUP_MIN_S", "GRAPH_CPU_GOAL_PERCENT",
           "CELL_SECOND_GOAL_MS", "SEEING_EXECUTABLES"]

#: Goal: RSS growth after the warm-up, at most this many percent.
GROWTH_GOAL_PERCENT = 5.0
#: The warm-up lasts at least this long, and at least one cycle of the scene [s].
WARMUP_MIN_S = 60.0
#: Goal: the recognition path's CPU (drivers with their simulator, window node(s), classifier) under one core
#: [% of one core].
GRAPH_CPU_GOAL_PERCENT = 100.0
#: Goal: CPU per cell and second of data across the recognition path [ms].
CELL_SECOND_GOAL_MS = 1.0
#: Nodes that serve seeing the skin (contact markers, the TF tree), not recognising: left out of the
#: recognition path's CPU and reported beside it.
SEEING_EXECUTABLES = ("contact_node", "tf_publisher")
#: Window node fault counters that mean a lost frame: a message's (BioTac batches) or a cell's batch in a body
#: part's message (a whole ``SkinPartFrames`` dropped on the way is every one of its cells' batches).
LOST_KEYS = ("fault_lost_frames", "fault_lost_cell_batches", "fault_bad_frames", "fault_sequence_restart")
#: The machine kept up when the simulated bus sent at least this share of the real rate.
KEEPS_UP_FRACTION = 0.99
#: Window node fault counters that mean a late (or out-of-order) frame.
LATE_KEYS = ("fault_windower_out_of_order", "fault_windower_duplicate", "fault_windower_clock_jump",
             "fault_windower_gap", "fault_windower_unsorted_stamps")


#: The drivers, whose process may simulate their bus on a thread of its own.
DRIVER_EXECUTABLES = ("biotac_driver", "skin_driver")


def _thread_cpu_s(process, thread_id: int | None) -> float | None:
    """CPU time of one thread of a psutil ``process`` [s] (``None``: no id, or no such thread)."""
    if thread_id is None:
        return None
    import psutil

    try:
        threads = process.threads()
    except psutil.NoSuchProcess:
        return None
    return next((t.user_time + t.system_time for t in threads if t.id == thread_id), None)


@dataclass
class NodeSamples:
    """RSS and CPU of one node process over the soak."""

    name: str
    executable: str
    pid: int
    t_s: list[float] = field(default_factory=list)
    rss_mb: list[float] = field(default_factory=list)
    cpu_s: list[float] = field(default_factory=list)
    #: CPU time of the thread simulating the scene in the driver's process [s] (``None``: not known at that
    #: sample); stays empty for a process without a simulator
    simulator_cpu_s: list[float | None] = field(default_factory=list)

    def rss_at(self, t_s: float) -> float | None:
        """RSS of the first sample at or after ``t_s`` [MB] (``None`` if the soak ended before)."""
        return next((r for t, r in zip(self.t_s, self.rss_mb) if t >= t_s), None)

    def growth_after_s(self, after_s: float) -> float | None:
        """Largest RSS after ``after_s`` relative to the RSS at ``after_s`` [%] (``None`` if too short)."""
        idx = [i for i, t in enumerate(self.t_s) if t >= after_s]
        if len(idx) < 2:
            return None
        ref = self.rss_mb[idx[0]]
        return 100.0 * (max(self.rss_mb[i] for i in idx) - ref) / ref

    def rate_mb_per_min(self, after_s: float) -> float | None:
        """Least-squares slope of RSS after ``after_s`` [MB/min]."""
        pts = [(t, r) for t, r in zip(self.t_s, self.rss_mb) if t >= after_s]
        if len(pts) < 3:
            return None
        n = len(pts)
        mt = sum(t for t, _ in pts) / n
        mr = sum(r for _, r in pts) / n
        den = sum((t - mt) ** 2 for t, _ in pts)
        return 60.0 * sum((t - mt) * (r - mr) for t, r in pts) / den if den else None

    def cpu_percent(self) -> float | None:
        """Mean CPU over the soak [% of one core]."""
        if len(self.t_s) < 2 or self.t_s[-1] <= self.t_s[0]:
            return None
        return 100.0 * (self.cpu_s[-1] - self.cpu_s[0]) / (self.t_s[-1] - self.t_s[0])

    def simulator_percent(self) -> float | None:
        """Mean CPU of the simulator's thread over the soak [% of one core] (``None``: no simulator seen).

        Its thread is known from the driver's diagnostics, which come after the first samples: a first
        sample without it counts as 0 s, as the process had just been started then."""
        if len(self.t_s) < 2 or not self.simulator_cpu_s or self.simulator_cpu_s[-1] is None \
                or self.t_s[-1] <= self.t_s[0]:
            return None
        first = self.simulator_cpu_s[0] or 0.0
        return 100.0 * (self.simulator_cpu_s[-1] - first) / (self.t_s[-1] - self.t_s[0])


@dataclass
class SoakReport:
    """What :func:`run_soak` measured."""

    robot: str
    scene_s: float
    seconds: float
    sample_s: float
    nodes: list[NodeSamples]
    diagnostics: dict[str, dict[str, str]]
    load_avg_start: tuple[float, float, float]
    load_avg_end: tuple[float, float, float]
    cpus: int
    nice: int
    exit_codes: dict[str, int | None]
    scene_frames_per_s: float = 0.0
    driver_run_s: float = 0.0
    frames_sent_in_run: int = 0
    cycle_s: float = 0.0  # one cycle of the scene (the demo once)
    cells: int = 0  # the robot's skin cells (and fingertips)
    #: (seconds from the start, status name, frames) each time a driver's ``bus_lost_frames`` grew
    loss_events: list[tuple[float, str, int]] = field(default_factory=list)
    #: node name -> the parameters the soak set on top of the robot's (``run_soak``'s ``overrides``)
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def warmup_s(self) -> float:
        """RSS growth is measured after this: the first minute or one cycle of the scene, whichever is longer [s]."""
        return max(WARMUP_MIN_S, self.cycle_s)

    def lost_frames(self) -> dict[str, int]:
        """Lost-frame counters of the window node(s), summed over nodes."""
        return self._sum(LOST_KEYS)

    def late_frames(self) -> dict[str, int]:
        """Late / out-of-order counters of the window node(s), summed over nodes."""
        return self._sum(LATE_KEYS)

    def _sum(self, keys: tuple[str, ...]) -> dict[str, int]:
        out = {k.removeprefix("fault_"): 0 for k in keys}
        for name, values in self.diagnostics.items():
            if name.split(": ")[-1] != "windows":
                continue
            for k in keys:
                out[k.removeprefix("fault_")] += int(float(values.get(k, 0)))
        return out

    def _node_sum(self, executable: str, key: str) -> int:
        """``key`` summed over the newest diagnostics of the nodes running ``executable``."""
        names = {n.name for n in self.nodes if n.executable == executable}
        total = 0
        for name, values in self.diagnostics.items():
            node = name.rpartition(": ")[0].split("/")[-1]
            if node in names and key in values:
                total += int(float(values[key]))
        return total

    def frames_split(self) -> dict[str, Any]:
        """Frames never sent (the simulator behind real time), lost on the bus, and sent but lost.

        See the module docstring.  The rate is judged from the driver's first
        diagnostics with frames to its last (``driver_run_s``, start-up left
        out): ``frames_sent_meanwhile`` against ``frames_due_at_real_rate``.
        ``machine_kept_up``: the simulated bus sent at least
        :data:`KEEPS_UP_FRACTION` of the real rate.
        """
        due = int(round(self.scene_frames_per_s * self.driver_run_s))
        sent = self._node_sum("skin_driver", "bus_frames")
        messages = self._node_sum("skin_driver", "messages")
        cell_batches = self._node_sum("skin_driver", "cell_batches")
        lost_msgs = self._sum(("fault_lost_frames",))["lost_frames"]
        lost_batches = self._sum(("fault_lost_cell_batches",))["lost_cell_batches"]
        rate = self.frames_sent_in_run / due if due else None
        # what the lost messages and cell batches carried, at the mean frames per message and per cell batch
        frames_lost = (lost_msgs * sent / messages if messages else 0) \
            + (lost_batches * sent / cell_batches if cell_batches else 0)
        return {"driver_run_s": self.driver_run_s, "frames_due_at_real_rate": due,
                "frames_sent_meanwhile": self.frames_sent_in_run, "never_sent": max(0, due - self.frames_sent_in_run),
                "sent_percent_of_real_rate": None if rate is None else 100.0 * rate, "frames_sent": sent,
                "machine_kept_up": rate is not None and rate >= KEEPS_UP_FRACTION,
                "lost_on_bus": self._node_sum("skin_driver", "bus_lost_frames"),
                "messages_sent": messages,
                "messages_received": self._sum(("frames_messages_taken",))["frames_messages_taken"],
                "messages_sent_and_lost": lost_msgs,
                "cell_batches_sent": cell_batches,
                "cell_batches_sent_and_lost": lost_batches,
                "frames_sent_and_lost": int(round(frames_lost))}

    def cpu(self) -> dict[str, Any]:
        """The graph's mean CPU [% of one core], whole and on the recognition path (every node but
        :data:`SEEING_EXECUTABLES`), and per node and on the path the CPU per cell and second of data [ms]:
        CPU time over ``cells`` times the seconds of data the simulated bus sent (its share of the real rate
        times the wall time), so a machine that fell behind is not credited for data it never sent."""
        per_node = {n.name: n.cpu_percent() for n in self.nodes}
        simulators = {n.name: v for n in self.nodes if (v := n.simulator_percent()) is not None}
        known = [v for v in per_node.values() if v is not None]
        path = [per_node[n.name] for n in self.nodes if n.executable not in SEEING_EXECUTABLES]
        graph = sum(known) if known else None
        path_percent = sum(v for v in path if v is not None) if path and None not in path else None
        rate = self.frames_split()["sent_percent_of_real_rate"]
        data_share = None if rate is None else min(rate, 100.0) / 100.0

        def per_cell_s(percent: float | None) -> float | None:
            if percent is None or not self.cells or not data_share:
                return None
            return 10.0 * percent / (self.cells * data_share)  # (percent / 100) s/s * 1000 ms/s / (cells * share)

        return {"graph_percent": graph, "recognition_path_percent": path_percent,
                "seeing_executables": list(SEEING_EXECUTABLES), "cells": self.cells,
                "data_share_of_real_rate": data_share,
                "ms_per_cell_second": {name: per_cell_s(v) for name, v in per_node.items()},
                "recognition_path_ms_per_cell_second": per_cell_s(path_percent),
                # the simulator runs on its own thread of the driver's process: what a robot's driver costs is
                # the process without it (the goals above are judged with it)
                "simulator_percent": simulators,
                "simulator_ms_per_cell_second": {name: per_cell_s(v) for name, v in simulators.items()},
                "recognition_path_ms_per_cell_second_without_simulator":
                    per_cell_s(None if path_percent is None else path_percent - sum(simulators.values()))}

    def rss_per_minute(self) -> dict[str, list[float]]:
        """Per node, the RSS of the first sample at or after every whole minute, from 0 [MB]."""
        out = {}
        for n in self.nodes:
            at = (n.rss_at(60.0 * minute) for minute in range(int(self.seconds // 60) + 1))
            out[n.name] = [round(r, 1) for r in at if r is not None]
        return out

    def pauses(self) -> dict[str, dict[str, float]]:
        """Per node, the garbage collector's runs and pauses (its ``process`` status) and, for a driver, the
        longest time between two reads and the reads that came late (its transport status)."""
        out: dict[str, dict[str, float]] = {}
        for name, values in self.diagnostics.items():
            node = name.rpartition(": ")[0]
            for key in ("gc_collections_g2", "gc_max_ms_g0", "gc_max_ms_g1", "gc_max_ms_g2", "gc_pause_ms_total",
                        "gc_settle_ms", "gc_frozen", "read_gap_max_ms", "read_gap_max_at_s", "read_gaps_long"):
                if key in values:
                    out.setdefault(node, {})[key] = float(values[key])
        return out

    def descriptors(self) -> int:
        """Descriptors published by the window node(s)."""
        return sum(int(float(v.get("descriptors_published", 0))) for n, v in self.diagnostics.items()
                   if n.split(": ")[-1] == "windows")

    def to_dict(self) -> dict[str, Any]:
        nodes = {}
        for n in self.nodes:
            nodes[n.name] = {
                "executable": n.executable, "pid": n.pid, "t_s": n.t_s, "rss_mb": n.rss_mb,
                "rss_start_mb": n.rss_mb[0] if n.rss_mb else None,
                "rss_at_warmup_mb": n.rss_at(self.warmup_s),
                "rss_end_mb": n.rss_mb[-1] if n.rss_mb else None,
                "rss_growth_after_warmup_percent": n.growth_after_s(self.warmup_s),
                "rss_rate_after_warmup_mb_per_min": n.rate_mb_per_min(self.warmup_s),
                "cpu_percent": n.cpu_percent()}
        growth = [v["rss_growth_after_warmup_percent"] for v in nodes.values()
                  if v["rss_growth_after_warmup_percent"] is not None]
        lost = self.lost_frames()
        split = self.frames_split()
        graph_lost = split["lost_on_bus"] + split["messages_sent_and_lost"] + split["cell_batches_sent_and_lost"] \
            + lost["bad_frames"] + lost["sequence_restart"]
        buffers = [float(v["windower_buffer_mb"]) for n, v in self.diagnostics.items()
                   if n.split(": ")[-1] == "windows" and "windower_buffer_mb" in v]
        cpu = self.cpu()
        return {"robot": self.robot, "seconds": self.seconds, "scene_s": self.scene_s, "cycle_s": self.cycle_s,
                "warmup_s": self.warmup_s, "sample_s": self.sample_s, "overrides": self.overrides,
                "cpus": self.cpus, "nice": self.nice, "load_avg_start": list(self.load_avg_start),
                "load_avg_end": list(self.load_avg_end), "nodes": nodes, "rss_per_minute_mb": self.rss_per_minute(),
                "windower_buffer_mb": sum(buffers) if buffers else None, "scene_frames_per_s": self.scene_frames_per_s,
                "driver_run_s": self.driver_run_s, "frames": split, "lost_frames": lost,
                "late_frames": self.late_frames(), "descriptors": self.descriptors(),
                "exit_codes": self.exit_codes, "cpu": cpu, "pauses": self.pauses(),
                "bus_loss_events": [{"t_s": round(t, 1), "status": name, "frames": n}
                                    for t, name, n in self.loss_events],
                "goal": {"rss_growth_max_percent": GROWTH_GOAL_PERCENT,
                         "rss_met": bool(growth) and max(growth) <= GROWTH_GOAL_PERCENT,
                         "no_lost_frames": not graph_lost,
                         "machine_kept_up": split["machine_kept_up"],
                         "recognition_path_cpu_max_percent": GRAPH_CPU_GOAL_PERCENT,
                         "cpu_met": None if cpu["recognition_path_percent"] is None
                         else bool(cpu["recognition_path_percent"] < GRAPH_CPU_GOAL_PERCENT),
                         "ms_per_cell_second_max": CELL_SECOND_GOAL_MS,
                         "cell_second_met": None if cpu["recognition_path_ms_per_cell_second"] is None
                         else bool(cpu["recognition_path_ms_per_cell_second"] <= CELL_SECOND_GOAL_MS)},
                "diagnostics": self.diagnostics}


def soak_scene(seconds: float, robot: str, out_dir: str | os.PathLike[str]) -> tuple[Path, float, float]:
    """The robot's demo scene played whole, over and over, to last ``seconds`` (plus 10 %), without simulated
    frame faults.

    Returns the scene file, its duration and the duration of one cycle (the demo once) [s].  Repeating each
    exploration in place instead would play the demo's last kind of touch only at the end of the soak, and
    a node's memory would grow there with the work, not with time.
    """
    from tactile_descriptors_ros.sim.scene import load_scene, scene_path

    base = scene_path(f"demo_{robot}")
    data = yaml.safe_load(base.read_text())
    one = load_scene(base).duration_s
    effects = data.get("effects") or {}
    for fault in ("dropped_frames", "corrupt_frames"):
        effects.pop(fault, None)
    data["effects"] = effects
    times = max(1, math.ceil(1.1 * float(seconds) / one))
    data["explorations"] = [dict(e) for _ in range(times) for e in data.get("explorations", [])]
    data["scene"]["name"] = f"soak_{robot}"
    path = Path(out_dir) / f"soak_{robot}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path, load_scene(path).duration_s, one


def scene_frames_per_s(scene: str | os.PathLike[str], first_s: float = 10.0) -> float:
    """Frames per second the scene's sensors send at real rate: every stream's samples over its first ``first_s``."""
    from tactile_descriptors_ros.sim.engine import iter_simulate
    from tactile_descriptors_ros.sim.scene import load_scene

    result = next(iter_simulate(load_scene(scene), max_chunk_s=first_s))
    frames, start, end = 0, None, None
    for cell in result.cells.values():
        for st in cell.streams.values():
            if st.t_ns.size:
                frames += int(st.t_ns.size)
                start = int(st.t_ns[0]) if start is None else min(start, int(st.t_ns[0]))
                end = int(st.t_ns[-1]) if end is None else max(end, int(st.t_ns[-1]))
    return frames / ((end - start) / 1e9) if frames and end > start else 0.0


def run_soak(seconds: float, robot: str = "nao", sample_s: float = 5.0,
             progress: Callable[[float, str], None] | None = None, verbose: bool = False,
             overrides: Mapping[str, Mapping[str, Any]] | None = None) -> SoakReport:
    """Run the robot's graph at full rate for ``seconds`` and sample it (see the module docstring).

    ``overrides``: node name -> parameters set on top of the robot's (``tactile bench --soak-set
    NODE.PARAM=VALUE``), e.g. to soak two settings of one parameter one after the other.

    Raises
    ------
    RuntimeError
        When a node exits during the soak (its last output lines are in the message).
    """
    import psutil

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray

    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    rob = load_robot(robot)
    tmp = tempfile.TemporaryDirectory(prefix="tactile_soak_")
    scene, scene_s, cycle_s = soak_scene(seconds, rob.name, tmp.name)
    # device stamps (the simulator's sample times), as the demo: on a loaded machine the simulator can
    # fall behind real time, and clock stamps would then be re-anchored instead of measuring the graph
    settings = {name: {"sim.speed": 1.0, "stamp_source": "device"} for name, e in rob.nodes.items()
                if e.get("executable") in DRIVER_EXECUTABLES}
    for name, params in (overrides or {}).items():
        settings.setdefault(name, {}).update(params)
    specs = build_graph(rob, sim_scene=scene, model_path=str(Path(tmp.name) / "model.json"), overrides=settings)
    procs = GraphProcesses(specs, env=localhost_environment(), output=sys.stderr if verbose else None)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("tactile_soak", context=context)
    diagnostics: dict[str, dict[str, str]] = {}
    bus_frames: dict[str, list[tuple[float, int]]] = {}  # per bus status: (time, frames) from its first frames on
    bus_lost: dict[str, int] = {}
    simulator_threads: dict[str, int] = {}  # node name -> native id of its simulator's thread
    loss_events: list[tuple[float, str, int]] = []  # seconds from the graph's start (t0, below)

    def on_diag(msg) -> None:
        now = time.monotonic()
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            diagnostics[st.name] = values
            if "device_simulator_thread_id" in values:
                simulator_threads[st.name.split(":")[0]] = int(values["device_simulator_thread_id"])
            if "bus_frames" in values and (int(values["bus_frames"]) or st.name in bus_frames):
                bus_frames.setdefault(st.name, []).append((now, int(values["bus_frames"])))
            if "bus_lost_frames" in values:
                lost = int(values["bus_lost_frames"])
                if lost > bus_lost.get(st.name, 0):
                    loss_events.append((now - t0, st.name, lost - bus_lost.get(st.name, 0)))
                bus_lost[st.name] = lost

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 100)
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    load_start = os.getloadavg()
    samples: list[NodeSamples] = []
    try:
        procs.start()
        handles = []
        for running in procs.nodes:
            samples.append(NodeSamples(running.spec.name, running.spec.executable, running.process.pid))
            handles.append(psutil.Process(running.process.pid))
        t0 = time.monotonic()
        next_sample = t0
        while True:
            now = time.monotonic()
            if now >= next_sample:
                for s, h in zip(samples, handles):
                    try:
                        mem = h.memory_info()
                        cpu = h.cpu_times()
                    except psutil.NoSuchProcess:
                        continue
                    s.t_s.append(round(now - t0, 3))
                    s.rss_mb.append(mem.rss / 2**20)
                    s.cpu_s.append(cpu.user + cpu.system)
                    if s.executable in DRIVER_EXECUTABLES:
                        s.simulator_cpu_s.append(_thread_cpu_s(h, simulator_threads.get(s.name)))
                if progress is not None:
                    progress(now - t0, ", ".join(f"{s.name} {s.rss_mb[-1]:.0f} MB" for s in samples if s.rss_mb))
                next_sample += sample_s
            dead = [r for r in procs.nodes if r.returncode is not None]
            if dead:
                lines = "\n".join(dead[0].lines[-20:])
                raise RuntimeError(f"node {dead[0].spec.name} exited with {dead[0].returncode} after "
                                   f"{now - t0:.0f} s:\n{lines}")
            if now - t0 >= seconds:
                break
            ex.spin_once(timeout_sec=min(0.2, max(0.0, next_sample - time.monotonic())))
        end = time.monotonic() + 2.0  # the newest diagnostics of every node
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.1)
    finally:
        procs.stop()
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    try:
        frames_per_s = scene_frames_per_s(scene)  # after the graph: it loads the machine for a few seconds
    finally:
        tmp.cleanup()
    runs = [(h[-1][0] - h[0][0], h[-1][1] - h[0][1]) for h in bus_frames.values() if len(h) >= 2]
    run_s = max((r for r, _ in runs), default=0.0)
    return SoakReport(robot=rob.name, scene_s=scene_s, seconds=float(seconds), sample_s=float(sample_s),
                      nodes=samples, diagnostics=diagnostics, load_avg_start=load_start,
                      load_avg_end=os.getloadavg(), cpus=os.cpu_count() or 1, nice=os.nice(0),
                      exit_codes={r.spec.name: r.returncode for r in procs.nodes},
                      scene_frames_per_s=frames_per_s, driver_run_s=run_s,
                      frames_sent_in_run=sum(n for _, n in runs), cycle_s=cycle_s, cells=rob.n_cells,
                      loss_events=loss_events, overrides={k: dict(v) for k, v in (overrides or {}).items()})


def format_soak(report: SoakReport) -> str:
    """The soak report as text."""
    d = report.to_dict()
    lines = [f"soak: {d['robot']} graph, {d['seconds']:.0f} s at full rate (scene {d['scene_s']:.0f} s), "
             f"{d['cpus']} CPUs, nice {d['nice']}, load {d['load_avg_start'][0]:.1f} -> {d['load_avg_end'][0]:.1f}",
             f"RSS growth after the warm-up: {d['warmup_s']:.0f} s (the first minute or one {d['cycle_s']:.0f} s "
             "cycle of the scene, whichever is longer)",
             f"{'node':<18} {'RSS start':>10} {'warm-up':>8} {'end':>8} {'growth':>8} {'MB/min':>8} {'CPU %':>7}"]

    def f(x, fmt):
        return "-" if x is None else format(x, fmt)

    for name, n in d["nodes"].items():
        lines.append(f"{name:<18} {f(n['rss_start_mb'], '10.1f')} {f(n['rss_at_warmup_mb'], '8.1f')} "
                     f"{f(n['rss_end_mb'], '8.1f')} {f(n['rss_growth_after_warmup_percent'], '7.1f')}% "
                     f"{f(n['rss_rate_after_warmup_mb_per_min'], '8.2f')} {f(n['cpu_percent'], '7.1f')}")
    for name, row in d["rss_per_minute_mb"].items():
        lines.append(f"{name:<18} RSS per minute [MB]: {' '.join(f'{r:.0f}' for r in row)}")
    if d["windower_buffer_mb"] is not None:
        lines.append(f"window node sample buffers: {d['windower_buffer_mb']:.1f} MB")
    fr = d["frames"]
    pct = fr["sent_percent_of_real_rate"]
    lines.append(f"frames over {fr['driver_run_s']:.0f} s of the driver's: {fr['frames_due_at_real_rate']} due at the "
                 f"real rate, {fr['frames_sent_meanwhile']} sent by the simulated bus "
                 f"({'-' if pct is None else format(pct, '.1f')} %), never sent {fr['never_sent']} (the simulator "
                 f"behind real time); lost on the bus {fr['lost_on_bus']}; sent and lost between driver and window "
                 f"node {fr['messages_sent_and_lost']} of {fr['messages_sent']} messages and "
                 f"{fr['cell_batches_sent_and_lost']} of {fr['cell_batches_sent']} cell batches "
                 f"({fr['frames_sent_and_lost']} frames)")
    lines.append(f"descriptors {d['descriptors']}; window node counters: lost {d['lost_frames']}; "
                 f"late {d['late_frames']}")
    if d["bus_loss_events"]:
        lines.append("frames lost on the bus at: " + ", ".join(f"{e['t_s']:.0f} s ({e['frames']})"
                                                             for e in d["bus_loss_events"]))
    for name, p in d["pauses"].items():
        lines.append(f"{name:<18} " + ", ".join(f"{k} {v:g}" for k, v in p.items()))
    c, verdict = d["cpu"], {True: "met", False: "NOT met", None: "-"}

    lines.append(f"CPU per cell and second of data [ms] ({c['cells']} cells): "
                 + ", ".join(f"{name} {f(v, '.2f')}" for name, v in c["ms_per_cell_second"].items()))
    if c["simulator_ms_per_cell_second"]:
        lines.append("of which the simulator's thread in the driver's process: "
                     + ", ".join(f"{name} {f(v, '.2f')}" for name, v in c["simulator_ms_per_cell_second"].items())
                     + f"; the recognition path without it "
                     f"{f(c['recognition_path_ms_per_cell_second_without_simulator'], '.2f')}")
    g = d["goal"]
    lines.append(f"goal: the recognition path's CPU (every node but {', '.join(c['seeing_executables'])}) under "
                 f"{g['recognition_path_cpu_max_percent']:.0f} % of a core: "
                 f"{f(c['recognition_path_percent'], '.1f')} %, {verdict[g['cpu_met']]} (the whole graph "
                 f"{f(c['graph_percent'], '.1f')} %); at most {g['ms_per_cell_second_max']:.1f} ms per "
                 f"cell-second: {f(c['recognition_path_ms_per_cell_second'], '.2f')}, "
                 f"{verdict[g['cell_second_met']]}")
    lost_goal = ("met" if g["no_lost_frames"] else "NOT met") + ("" if g["machine_kept_up"] else
                                                                 " (not judged: the machine did not keep up)")
    lines.append(f"goal: RSS growth after the first minute <= {g['rss_growth_max_percent']:.0f} %: "
                 f"{'met' if g['rss_met'] else 'NOT met'}; no lost frames when the machine keeps up: {lost_goal}")
    return "\n".join(lines)

