"""A large skin through the ROS node graph in real time (``tactile bench --scale-graph``).

What runs is a real launch graph, as ``tactile launch ROBOT.yaml
--split-window-nodes`` starts it: a synthetic robot description of
``n_cells`` NAO skin cells (the ``skin_cell`` type of ``config/nao.yaml``)
split into ``parts`` equal body parts, with a ``nodes:`` section of one
``skin_driver`` per body part (each its own bus) and one window node that
the launch graph's scale-out option splits into one window node per body
part; every node is its own process.  Windows are fixed, 2 s long with a
0.5 s hop, and the descriptor is the paper's (``groups`` to change it).

Each driver runs the ``simulated`` transport with ``sim.loop``: its body
part's cells play a 2 s scene of one sliding touch over and over as CAN
frames in the skin layout (:class:`~..sim.sources.LoopedSkinCanSource`),
simulated once at start, so the driver decodes real wire frames at full
rate (accelerometer 1 kHz, force and proximity 250 Hz, temperature 10 Hz)
without simulating them live.  Stamps are the bus times (``stamp_source:
device``).  The harness never touches the messages between drivers and
window nodes: it reads what the nodes say on ``/diagnostics`` and the
descriptors they publish, so it measures whichever message type the driver
publishes.

Measured after every window node has published its first descriptor (the
warm-up: start-up, kernel load, the drivers' one simulation), for
``seconds``:

* CPU of every process (psutil, user + system, % of one core) and RSS;
* per body part: messages the driver published and the window node
  received, lost frames (sequence gaps seen by the window node, lost frames
  the driver counted on the bus, frames the window node found late or
  missing in a window: ``windower_gap`` and the out-of-order counters),
  descriptors produced against expected (one per hop of wall time), and the
  real-time factor: simulated seconds windowed per wall second (the slope
  of the windows' end stamps over their arrival times) and how much the
  lag (arrival minus end stamp) grew over the run.

A body part *keeps up* when it lost no frame, produced at least the
expected descriptors less one, and its lag grew by less than one hop; the
graph keeps up when every body part does.  On a shared machine this is a
fact about the machine as much as about the graph: the load average is
part of the result.
"""

from __future__ import annotations

import contextlib
import math
import os
import random
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_descriptors_lab.bench.multi_host import MultiHostResult
from tactile_descriptors_lab.bench.netns import LinkCounters
from tactile_descriptors_lab.bench.soak import LATE_KEYS, LOST_KEYS
from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.sim.synthetic import (
    WINDOW_HOP_S,
    WINDOW_LENGTH_S,
    cell_samples_per_s,
    part_name,
    scale_robot_files,
    split_cells,
)

__all__ = [
    "ProcessLoad",
    "PartResult",
    "ScaleGraphReport",
    "scale_graph_specs",
    "run_scale_graph",
    "format_scale_graph",
    "CELLS_PER_PART",
]

#: Default body part size (cells) when the number of body parts is not given.
CELLS_PER_PART = 500
#: A driver keeps up when it decodes at least this share of its cells' samples per wall second.
DRIVER_RTF_MIN = 0.98
#: The window node's descriptor queue depth (``qos.descriptor.depth``) when the robot does not set it.
WINDOW_DESCRIPTOR_DEPTH = 10
#: The graph is stopped when the machine has less memory available than this [GB] (it is shared).
MEMORY_FLOOR_GB = 3.0
#: Longest wait for every node's diagnostics at the start and the end of the measurement [s]; a node
#: that is later than this (an overloaded machine) is reported in ``stale_diagnostics``.
DIAGNOSTICS_WAIT_S = 30.0


def scale_graph_specs(robot_path: str | os.PathLike[str], model_path: str | None = None) -> list:
    """The node specs of a scale robot: its drivers, one window node per body part, its classifier if it has one."""
    from tactile_descriptors_ros.launching.graph import build_graph

    return build_graph(robot_path, split_window_nodes=True, model_path=model_path)


# ------------------------------------------------------------------ results
@dataclass
class ProcessLoad:
    """CPU and memory of one node process over the measurement."""

    name: str
    executable: str
    pid: int
    cells: int
    body_parts: tuple[str, ...] = ()
    cpu_percent: float | None = None
    rss_mb: float | None = None
    #: simulated seconds the process handled per wall second (its body parts' driver or window real-time factor)
    data_realtime_factor: float | None = None

    @property
    def cpu_ms_per_cell_s(self) -> float | None:
        """CPU per cell and wall second [ms] (cpu_percent * 10 / cells)."""
        return None if self.cpu_percent is None or not self.cells else self.cpu_percent * 10.0 / self.cells

    @property
    def cpu_ms_per_cell_data_s(self) -> float | None:
        """CPU per cell and second of sensor data handled [ms]: the demand, also of a process that fell behind."""
        per_wall = self.cpu_ms_per_cell_s
        rtf = self.data_realtime_factor
        return None if per_wall is None or not rtf or rtf <= 0 else round(per_wall / rtf, 4)


@dataclass
class PartResult:
    """One body part's path from its driver to its window node."""

    name: str
    cells: int
    messages_sent: int | None = None
    messages_received: int | None = None
    lost: dict[str, int] = field(default_factory=dict)
    late: dict[str, int] = field(default_factory=dict)
    bus_lost_frames: int | None = None
    driver_realtime_factor: float | None = None
    windows: int = 0
    windows_expected: float = 0.0
    realtime_factor: float | None = None
    lag_growth_s: float | None = None
    cells_in_contact: int | None = None

    @property
    def lost_frames(self) -> int:
        """Every frame lost between the bus and the window: sequence gaps, bus losses, late or missing frames."""
        return sum(self.lost.values()) + sum(self.late.values()) + int(self.bus_lost_frames or 0)

    @property
    def kept_up(self) -> bool:
        """No frame lost, the expected windows (less one) produced, a lag that grew by less than one hop."""
        return (self.lost_frames == 0 and self.windows >= math.floor(self.windows_expected) - 1
                and self.lag_growth_s is not None and self.lag_growth_s < WINDOW_HOP_S
                and self.driver_realtime_factor is not None and self.driver_realtime_factor >= DRIVER_RTF_MIN)


@dataclass
class ScaleGraphReport:
    """What :func:`run_scale_graph` measured."""

    n_cells: int
    parts: list[PartResult]
    processes: list[ProcessLoad]
    seconds: float
    warm_up_s: float
    groups: tuple[str, ...]
    one_driver: bool
    load_avg_start: tuple[float, float, float]
    load_avg_end: tuple[float, float, float]
    cpus: int
    exit_codes: dict[str, int | None] = field(default_factory=dict)
    #: body parts without a descriptor when the warm-up timed out (measured anyway)
    silent_at_start: list[str] = field(default_factory=list)
    #: statuses whose last counters are older than the end of the measurement
    stale_diagnostics: list[str] = field(default_factory=list)
    #: across hosts (``hosts`` >= 1): placement, traffic, discovery, predictions, the link drop
    multi_host: MultiHostResult | None = None
    #: why the graph was stopped before the end of the measurement (the machine's memory), if it was
    stopped: str | None = None

    @property
    def kept_up(self) -> bool:
        return not self.stopped and bool(self.parts) and all(p.kept_up for p in self.parts)

    def _hosts_kept_up(self) -> bool:
        """Across hosts: every frame path kept up, and every body part whose host's link stayed up kept up too,
        lost no descriptor on the way to the classifier, and got every prediction back."""
        mh = self.multi_host
        if mh is None or not self.parts or self.stopped:
            return False
        dropped = mh.link_drop.host if mh.link_drop is not None else None
        frames_ok = all(p.lost_frames == 0 and p.driver_realtime_factor is not None
                        and p.driver_realtime_factor >= DRIVER_RTF_MIN for p in self.parts)
        linked = [p for p in self.parts if mh.placement_of_part(p.name) != dropped]
        return (frames_ok and all(p.kept_up and mh.descriptor_gaps.get(p.name, 1) == 0 for p in linked)
                and all(v["missing"] == 0 and v["sent"] > 0 for h, v in mh.predictions.items() if h != dropped))

    @property
    def lost_frames(self) -> int:
        return sum(p.lost_frames for p in self.parts)

    def cpu_by_executable(self) -> dict[str, dict[str, float | None]]:
        """Per executable: processes, total CPU [% of one core], CPU per cell and second [ms]."""
        out: dict[str, dict[str, float | None]] = {}
        for exe in dict.fromkeys(p.executable for p in self.processes):
            ps = [p for p in self.processes if p.executable == exe]
            cpu = [p.cpu_percent for p in ps if p.cpu_percent is not None]
            total = sum(cpu) if len(cpu) == len(ps) else None
            demand = [p.cpu_ms_per_cell_data_s * p.cells for p in ps if p.cpu_ms_per_cell_data_s is not None]
            out[exe] = {"processes": len(ps), "cpu_percent": total,
                        "cpu_ms_per_cell_s": None if total is None else round(total * 10.0 / self.n_cells, 4),
                        "cpu_ms_per_cell_data_s": round(sum(demand) / self.n_cells, 4)
                        if len(demand) == len(ps) else None}
        return out

    def targets(self) -> dict[str, dict[str, Any]]:
        """The graph target, with ``met``."""
        rtf = [p.realtime_factor for p in self.parts if p.realtime_factor is not None]
        return {f"skin_{self.n_cells}_graph": {
            "target": f"{self.n_cells} skin cells through drivers and one window node per body part in real time "
                      f"({WINDOW_LENGTH_S:g} s windows, {WINDOW_HOP_S:g} s hop), zero lost frames",
            "cells": self.n_cells, "processes": len(self.processes),
            "lost_frames": self.lost_frames,
            "windows": sum(p.windows for p in self.parts),
            "windows_expected": round(sum(p.windows_expected for p in self.parts), 1),
            "realtime_factor_min": min(rtf) if len(rtf) == len(self.parts) and rtf else None,
            "cpu_percent_total": sum(p.cpu_percent or 0.0 for p in self.processes),
            "met": self.kept_up}} if self.multi_host is None else self._host_targets()

    def _host_targets(self) -> dict[str, dict[str, Any]]:
        mh = self.multi_host
        assert mh is not None
        rtf = [p.realtime_factor for p in self.parts if p.realtime_factor is not None]
        out: dict[str, dict[str, Any]] = {f"skin_{self.n_cells}_graph_{mh.hosts}_hosts": {
            "target": f"{self.n_cells} skin cells, each body part's driver and window node on one of {mh.hosts} "
                      "hosts, the classifier on another, in real time: zero lost frames, every descriptor at the "
                      "classifier, every prediction back on every body-part host (a host whose link was dropped "
                      "is judged by the link drop target)",
            "cells": self.n_cells, "hosts": mh.hosts, "processes": len(self.processes),
            "lost_frames": self.lost_frames, "descriptors_lost": mh.descriptors_lost,
            "predictions_missing": mh.predictions_missing,
            "windows": sum(p.windows for p in self.parts),
            "windows_expected": round(sum(p.windows_expected for p in self.parts), 1),
            "realtime_factor_min": min(rtf) if len(rtf) == len(self.parts) and rtf else None,
            "cross_host_bytes_per_cell_s": mh.to_dict()["cross_host_bytes_per_cell_s"],
            "met": self._hosts_kept_up()},
            "discovery": {
                "target": f"a participant joining on the classifier's host sees every node and descriptor publisher "
                          f"of the graph within one window ({WINDOW_LENGTH_S:g} s)",
                "discovery_s": None if mh.discovery_s is None else round(mh.discovery_s, 3),
                "met": mh.discovery_s is not None and mh.discovery_s <= WINDOW_LENGTH_S}}
        drop = mh.link_drop
        if drop is not None:
            backlog = max(drop.backlog.values(), default=0)
            out["link_drop_recovery"] = {
                "target": f"a body-part host's link down for {drop.down_s:.1f} s: descriptors and predictions lost "
                          f"are counted, the backlog delivered afterwards is at most the descriptor queue depth "
                          f"({drop.queue_depth}), descriptors arrive with their usual lag again within one window "
                          f"({WINDOW_LENGTH_S:g} s) of the link's return",
                "host": drop.host, "down_s": round(drop.down_s, 3),
                "descriptors_missing": sum(drop.descriptors_missing.values()),
                "predictions_missing": drop.predictions_missing, "backlog_max": backlog,
                "recovered_after_s_max": max((t for t in drop.recovered_after_s.values() if t is not None),
                                             default=None),
                "missing_after_recovery": sum(drop.missing_after_recovery.values()),
                "met": drop.recovered_within(WINDOW_LENGTH_S) and backlog <= drop.queue_depth
                and not any(drop.missing_after_recovery.values())}
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "targets": self.targets(),
            "n_cells": self.n_cells, "body_parts": len(self.parts), "seconds": self.seconds,
            "warm_up_s": self.warm_up_s, "groups": list(self.groups), "one_driver": self.one_driver,
            "window_length_s": WINDOW_LENGTH_S, "window_hop_s": WINDOW_HOP_S,
            "kept_up": self.kept_up, "lost_frames": self.lost_frames,
            "cpu_by_executable": self.cpu_by_executable(),
            "processes": {p.name: {"executable": p.executable, "pid": p.pid, "cells": p.cells,
                                   "cpu_percent": p.cpu_percent, "cpu_ms_per_cell_s": p.cpu_ms_per_cell_s,
                                   "data_realtime_factor": p.data_realtime_factor,
                                   "cpu_ms_per_cell_data_s": p.cpu_ms_per_cell_data_s,
                                   "rss_mb": p.rss_mb} for p in self.processes},
            "parts": {p.name: {"cells": p.cells, "messages_sent": p.messages_sent,
                               "messages_received": p.messages_received, "lost": p.lost, "late": p.late,
                               "bus_lost_frames": p.bus_lost_frames, "lost_frames": p.lost_frames,
                               "driver_realtime_factor": p.driver_realtime_factor,
                               "windows": p.windows, "windows_expected": round(p.windows_expected, 1),
                               "realtime_factor": p.realtime_factor, "lag_growth_s": p.lag_growth_s,
                               "cells_in_contact": p.cells_in_contact, "kept_up": p.kept_up}
                      for p in self.parts},
            "cpus": self.cpus, "load_avg_start": list(self.load_avg_start), "load_avg_end": list(self.load_avg_end),
            "exit_codes": self.exit_codes, "silent_at_start": self.silent_at_start,
            "stale_diagnostics": self.stale_diagnostics,
            "multi_host": None if self.multi_host is None else self.multi_host.to_dict(),
            "stopped": self.stopped,
        }


# --------------------------------------------------------------------- run
class _Monitor:
    """Descriptors (arrival time, end stamp, body part) and the newest diagnostics of every node."""

    def __init__(self, node: Any) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.serialization import serialize_message

        from tactile_descriptors_msgs.msg import Descriptor

        self._serialize = serialize_message
        self.lock = threading.Lock()
        self.updated = threading.Condition(self.lock)
        self.windows: dict[str, list[tuple[float, int, int]]] = {}
        self.diagnostics: dict[str, dict[str, str]] = {}
        self.diagnostics_at: dict[str, float] = {}
        self.task_failures: dict[str, str] = {}
        self.first_window = threading.Event()
        self.expected_parts: set[str] = set()
        #: serialized bytes received per kind: ``descriptor``, ``diagnostics`` (of nodes whose name does not
        #: start with one of :attr:`local_nodes`), ``diagnostics_local``
        self.payload: Counter[str] = Counter()
        self.local_nodes: tuple[str, ...] = ()
        node.create_subscription(Descriptor, "/tactile/descriptor", self._on_descriptor, 100)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 100)

    def _on_descriptor(self, msg: Any) -> None:
        now = time.monotonic()
        end_ns = msg.window_end.sec * 1_000_000_000 + msg.window_end.nanosec
        part = ",".join(msg.body_parts)
        contact = int(sum(msg.cells_in_contact))
        size = len(self._serialize(msg))
        with self.lock:
            self.payload["descriptor"] += size
            self.windows.setdefault(part, []).append((now, end_ns, contact))
            if self.expected_parts and self.expected_parts <= set(self.windows):
                self.first_window.set()

    def _on_diagnostics(self, msg: Any) -> None:
        now = time.monotonic()
        size = len(self._serialize(msg))
        local = bool(msg.status) and msg.status[0].name.startswith(self.local_nodes) if self.local_nodes else False
        with self.updated:
            self.payload["diagnostics_local" if local else "diagnostics"] += size
            for st in msg.status:
                if st.message.startswith("diagnostic task failed"):  # no counters: keep the last ones
                    self.task_failures[st.name] = st.message
                    continue
                self.diagnostics[st.name] = {kv.key: kv.value for kv in st.values}
                self.diagnostics_at[st.name] = now
            self.updated.notify_all()

    def payload_bytes(self) -> Counter[str]:
        """A copy of :attr:`payload`."""
        with self.lock:
            return Counter(self.payload)

    def snapshot(self) -> dict[str, dict[str, str]]:
        """The newest diagnostics of every node (a copy)."""
        with self.lock:
            return {k: dict(v) for k, v in self.diagnostics.items()}

    def stale_since(self, t: float) -> list[str]:
        """Statuses not published since ``t``."""
        with self.lock:
            return sorted(k for k, v in self.diagnostics_at.items() if v <= t)

    def wait_diagnostics_after(self, t: float, timeout_s: float) -> bool:
        """Wait until every node seen so far has published diagnostics after ``t`` (False on timeout)."""
        with self.updated:
            return self.updated.wait_for(lambda: all(v > t for v in self.diagnostics_at.values()), timeout_s)


def _int(values: dict[str, str], key: str) -> int | None:
    v = values.get(key)
    return None if v is None else int(float(v))


def _part_timing(rows: list[tuple[float, int, int]], t0: float, t1: float) -> tuple[int, float | None, float | None]:
    """Windows arriving in [t0, t1], the slope of end stamps over arrival times, and the lag growth [s]."""
    sel = [(t, e) for t, e, _ in rows if t0 <= t <= t1]
    if len(sel) < 3:
        return len(sel), None, None
    t = np.array([a for a, _ in sel])
    e = np.array([b for _, b in sel], dtype=np.float64) * 1e-9
    slope = float(np.polyfit(t - t[0], e - e[0], 1)[0])
    lag = t - e
    k = max(1, min(4, len(sel) // 4))
    growth = float(np.median(lag[-k:]) - np.median(lag[:k]))
    return len(sel), round(slope, 4), round(growth, 4)


def run_scale_graph(n_cells: int, *, parts: int | None = None, seconds: float = 30.0, settle_s: float = 5.0,
                    groups: Sequence[str] = ("paper",), batch_s: float | None = None,
                    read_period_s: float | None = None, one_driver: bool = False,
                    warm_up_timeout_s: float = 180.0, window_parameters: dict[str, Any] | None = None,
                    hosts: int = 0, link_drop_s: float | None = None, link_drop_host: int = 0,
                    discovery: str = "subnet", progress: Callable[[float, str], None] | None = None,
                    verbose: bool = False) -> ScaleGraphReport:
    """Run the scale graph (module docstring) and measure it for ``seconds`` after the warm-up.

    Parameters
    ----------
    n_cells : int
        Skin cells.
    parts : int, optional
        Body parts (default: one per :data:`CELLS_PER_PART` cells, at least one).
    seconds : float
        Measurement time.
    settle_s : float
        Time between the first descriptor of every body part and the
        measurement (the backlog of the start-up drains).
    groups, batch_s, read_period_s, one_driver, window_parameters
        See :func:`scale_robot_files`.
    warm_up_timeout_s : float
        Longest wait for the first descriptor of every body part; the
        measurement starts then anyway (``silent_at_start`` names the body
        parts still without one: a graph too large for the machine still
        gets its per-process figures).
    hosts : int
        0: every process on this machine's own network, discovery on
        localhost.  ``H`` >= 1: ``H`` body-part hosts and a classifier host,
        network namespaces joined by veth links (:mod:`.multi_host`), with a
        classifier node; the report gains ``multi_host``.
    link_drop_s : float, optional
        With ``hosts``: pull body-part host ``link_drop_host``'s cable for
        this long, a third of the way into the measurement.
    discovery : str
        With ``hosts``: ``subnet`` (DDS's simple discovery, multicast on the
        hosts' links) or ``server`` (a Fast DDS discovery server on the
        classifier's host, every participant its client).
    progress : callable, optional
        Called with the seconds measured so far and a short status line.
    verbose : bool
        Forward the nodes' output to stderr.

    Raises
    ------
    RuntimeError
        When a node exits (its last lines of output are in the message).
    ConfigError
        For impossible sizes.
    """
    import psutil

    from . import multi_host as mh

    if not seconds > 0:
        raise ConfigError(f"the measurement needs a positive time, got {seconds}", key="seconds")
    parts = parts if parts is not None else max(1, math.ceil(n_cells / CELLS_PER_PART))
    if hosts < 0 or (hosts and hosts > parts):
        raise ConfigError(f"{parts} body parts cannot be placed on {hosts} hosts", key="hosts")
    if hosts > 1 and one_driver:
        raise ConfigError("one driver for every body part cannot be split over several hosts", key="hosts")
    if link_drop_s is not None:
        if not hosts:
            raise ConfigError("a link drop needs hosts", key="link_drop_s")
        if not 0 <= link_drop_host < hosts:
            raise ConfigError(f"no body-part host {link_drop_host} (0 to {hosts - 1})", key="link_drop_host")
        if not link_drop_s > 0 or seconds < link_drop_s + 3 * WINDOW_LENGTH_S:
            raise ConfigError(f"a {link_drop_s} s link drop needs a positive time and a measurement of at least "
                              f"{3 * WINDOW_LENGTH_S:g} s more", key="link_drop_s")
    if discovery not in mh.DISCOVERY_MODES:
        raise ConfigError(f"must be one of {mh.DISCOVERY_MODES}, got {discovery!r}", key="discovery")
    say = progress or (lambda measured_s, text: None)
    # outside the hosts (this process, and every node without hosts) discovery stays on this machine
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    stack = contextlib.ExitStack()
    tmp = stack.enter_context(tempfile.TemporaryDirectory(prefix="tactile_scale_"))
    robot_path = scale_robot_files(n_cells, parts, tmp, groups=groups, batch_s=batch_s,
                                   read_period_s=read_period_s, one_driver=one_driver,
                                   window_parameters=window_parameters, classifier=bool(hosts))
    specs = scale_graph_specs(robot_path, model_path=os.path.join(tmp, "classifier_model.json") if hosts else None)
    runs = dict(zip((part_name(k, parts) for k in range(parts)), split_cells(n_cells, parts)))
    cells_of = {s.name: sum(len(runs[p]) for p in s.parameters.get("body_parts", [])) for s in specs}
    # what bounds a host's backlog of descriptors while its link is down: the window nodes' queue
    descriptor_depth = max(int(s.parameters.get("qos.descriptor.depth", WINDOW_DESCRIPTOR_DEPTH))
                           for s in specs if s.executable == "window_node")
    net = None
    placement: dict[str, str] = {}
    part_host: dict[str, str] = {}
    proc_args: dict[str, Any] = {}
    if hosts:
        from .netns import VirtualHosts

        part_host = mh.assign_parts(list(runs), hosts)
        placement = mh.node_hosts(specs, part_host)
        net = VirtualHosts(mh.host_names(hosts))
        # inside the hosts discovery goes over SUBNET (or to the server): their only links are the bench's own
        host_env = mh.discovery_env(discovery, net.address(mh.CLASSIFIER_HOST))
        proc_args = {"prefix": {n: net.exec_prefix(h) for n, h in placement.items()},
                     "node_env": {n: host_env for n in placement}}
    procs = GraphProcesses(specs, env=localhost_environment(), output=sys.stderr if verbose else None, **proc_args)
    ros_threads: list[mh.RosThread] = []
    load_start = os.getloadavg()
    loads: list[ProcessLoad] = []
    cpu0: dict[int, float] = {}
    silent: list[str] = []
    stale: list[str] = []
    stopped: str | None = None
    extra = MultiHostResult(hosts=hosts, discovery=discovery, placement=placement,
                            part_hosts=part_host) if hosts else None
    try:
        if net is not None:
            stack.enter_context(net)  # removed last of all, after every process on it has stopped
            say(0.0, f"made {hosts + 1} hosts")
            if discovery == "server":
                server = mh.DiscoveryServer(net.exec_prefix(mh.CLASSIFIER_HOST), net.address(mh.CLASSIFIER_HOST),
                                            localhost_environment())
                stack.callback(server.stop)
        monitor_ns = net.namespace(mh.CLASSIFIER_HOST) if net is not None else None
        ros_env = host_env if net is not None else None
        observer = mh.RosThread("tactile_scale_graph", _Monitor, monitor_ns, env=ros_env)
        ros_threads.append(observer)
        observer.start()
        monitor: _Monitor = observer.value
        monitor.expected_parts = set(runs)
        monitor.local_nodes = tuple(n for n, h in placement.items() if h == mh.CLASSIFIER_HOST)
        listeners: dict[str, mh.PredictionLog] = {}
        if net is not None:
            classifier_log = mh.RosThread("tactile_predictions_classifier",
                                          lambda node: mh.PredictionLog().subscribe(node), monitor_ns, env=ros_env)
            ros_threads.append(classifier_log)
            classifier_log.start()
            listeners[mh.CLASSIFIER_HOST] = classifier_log.value
            env = {**localhost_environment(), **host_env}
            for h in mh.host_names(hosts)[:-1]:
                listener = mh.PredictionListener(net.exec_prefix(h), env)
                stack.callback(listener.stop)
                listener.wait_ready()
                listeners[h] = listener.log
        say(0.0, f"starting {len(specs)} processes")
        procs.start()
        handles = {}
        for r in procs.nodes:
            loads.append(ProcessLoad(r.spec.name, r.spec.executable, r.process.pid, cells_of.get(r.spec.name, 0),
                                     tuple(r.spec.parameters.get("body_parts", []))))
            handles[r.process.pid] = psutil.Process(r.process.pid)
        t_start = time.monotonic()
        while not monitor.first_window.wait(0.5):
            _check_alive(procs, t_start)
            stopped = _memory_short(procs, t_start)
            if stopped:
                with monitor.lock:
                    silent = sorted(set(runs) - set(monitor.windows))
                break
            waited = time.monotonic() - t_start
            if waited > warm_up_timeout_s:  # measure anyway: the processes' load is the result then
                with monitor.lock:
                    silent = sorted(set(runs) - set(monitor.windows))
                break
            say(0.0, f"warming up ({waited:.0f} s)")
        settle_end = time.monotonic() + float(settle_s)
        while time.monotonic() < settle_end and not stopped:
            _check_alive(procs, t_start)
            stopped = _memory_short(procs, t_start)
            say(0.0, "settling")
            time.sleep(min(0.5, max(0.0, settle_end - time.monotonic())))
        warm_up_s = time.monotonic() - t_start
        if extra is not None:
            say(0.0, "timing discovery")
            extra.discovery_s = None if stopped else mh.discovery_time(monitor_ns, [s.name for s in specs],
                                                  sum(s.executable == "window_node" for s in specs), env=ros_env)
            extra.start_up_traffic = {h: net.counters(h).to_dict() for h in net.hosts}
        # the counters at the start of the measurement: the warm-up's faults (cells starting at different
        # times, the kernel loading) are not the graph's steady state; a graph stopped before it is measured
        # from its start
        if not stopped:
            t_mark = time.monotonic()
            monitor.wait_diagnostics_after(t_mark, timeout_s=DIAGNOSTICS_WAIT_S)  # an overloaded node may be late
        before = monitor.snapshot() if not stopped else {}
        t0 = time.monotonic() if not stopped else t_start
        for p in loads:
            c = handles[p.pid].cpu_times()
            cpu0[p.pid] = c.user + c.system if not stopped else 0.0
        links0 = {h: net.counters(h) if not stopped else LinkCounters(0, 0, 0, 0, 0, 0) for h in net.hosts} \
            if net is not None else {}
        payload0 = monitor.payload_bytes() if not stopped else Counter()
        predictions0 = listeners[mh.CLASSIFIER_HOST].payload_bytes() if net is not None and not stopped else 0
        deadline = t0 + float(seconds)
        drop_at = t0 + (float(seconds) - float(link_drop_s)) / 3.0 if link_drop_s else None
        drop = None
        while time.monotonic() < deadline and not stopped:
            _check_alive(procs, t_start)
            stopped = _memory_short(procs, t_start)
            now = time.monotonic()
            if drop_at is not None and drop is None and now >= drop_at:
                host = mh.host_names(hosts)[link_drop_host]
                net.set_link(host, False)
                drop = mh.LinkDrop(host, time.monotonic(), math.inf, queue_depth=descriptor_depth)
                say(now - t0, f"link of {host} down")
            if drop is not None and drop.up_at == math.inf and now >= drop.down_at + float(link_drop_s):
                net.set_link(drop.host, True)
                drop.up_at = time.monotonic()
            wake = [deadline, now + 0.5]
            if drop_at is not None and drop is None:
                wake.append(drop_at)
            if drop is not None and drop.up_at == math.inf:
                wake.append(drop.down_at + float(link_drop_s))
            time.sleep(max(0.0, min(wake) - time.monotonic()))
            say(time.monotonic() - t0, "measuring")
        t1 = time.monotonic()
        links1 = {h: net.counters(h) for h in net.hosts} if net is not None else {}
        payload1 = monitor.payload_bytes()
        predictions1 = listeners[mh.CLASSIFIER_HOST].payload_bytes() if net is not None else 0
        for p in loads:
            h = handles[p.pid]
            c = h.cpu_times()
            p.cpu_percent = round(100.0 * (c.user + c.system - cpu0[p.pid]) / (t1 - t0), 2)
            p.rss_mb = round(h.memory_info().rss / 2**20, 1)
        # counters of diagnostics published after the measurement cover all of it
        if not monitor.wait_diagnostics_after(t1, timeout_s=DIAGNOSTICS_WAIT_S):
            stale = monitor.stale_since(t1)
        after = monitor.snapshot()
        load_end = os.getloadavg()
        if extra is not None:
            extra.traffic = {h: (links1[h] - links0[h]).to_dict() for h in net.hosts}
            # what the messages themselves weigh (serialized), beside what the links carried
            extra.payload = {"descriptors": payload1["descriptor"] - payload0["descriptor"],
                             "diagnostics": payload1["diagnostics"] - payload0["diagnostics"],
                             "predictions_per_host": predictions1 - predictions0}
            # predictions the classifier's host got during the measurement, up to a second before its end, must
            # have reached every host (those of the start-up may precede a host's subscription being matched)
            sent = listeners[mh.CLASSIFIER_HOST].ends(until=t1 - 1.0, since=t0)
            extra.predictions = {h: {"sent": int(sum(sent.values())),
                                     "received": int(sum(log.ends().values())),
                                     "missing": mh.missing_predictions(sent, log.ends())}
                                 for h, log in listeners.items() if h != mh.CLASSIFIER_HOST}
            extra.link_drop = drop
    finally:
        codes = procs.stop()
        for t in reversed(ros_threads):
            t.stop()
        stack.close()
    results = _parts(monitor, before, after, runs, t0, t1)
    by_part = {r.name: r for r in results}
    for p in loads:
        rtf = [by_part[b].driver_realtime_factor if p.executable == "skin_driver" else by_part[b].realtime_factor
               for b in p.body_parts if b in by_part]
        if rtf and all(x is not None for x in rtf):
            p.data_realtime_factor = round(float(np.mean(rtf)), 4)
    if extra is not None:
        _multi_host_results(extra, monitor, before, after, part_host, runs, t0, t1, n_cells)
    return ScaleGraphReport(n_cells, results, loads, round(t1 - t0, 2) if stopped else float(seconds),
                            round(warm_up_s, 2), tuple(groups), one_driver, load_start, load_end, os.cpu_count() or 1,
                            codes, silent, stale, extra, stopped)


def _multi_host_results(extra: MultiHostResult, monitor: _Monitor, before: dict[str, dict[str, str]],
                        after: dict[str, dict[str, str]], part_host: dict[str, str], runs: dict[str, range],
                        t0: float, t1: float, n_cells: int) -> None:
    """Descriptors lost on the way, the classifier's counters, the link drop's account."""
    from . import multi_host as mh

    hop_ns = int(round(WINDOW_HOP_S * 1e9))
    with monitor.lock:
        rows = {p: [(t, e) for t, e, _ in monitor.windows.get(p, []) if t0 <= t <= t1] for p in runs}
    extra.descriptor_gaps = {p: mh.descriptor_gaps([e for _, e in r], hop_ns) for p, r in rows.items()}
    extra.cells_per_host = {h: sum(len(runs[p]) for p, hp in part_host.items() if hp == h)
                            for h in dict.fromkeys(part_host.values())}
    extra.seconds = t1 - t0
    extra.n_cells = n_cells
    # the classifier's own status (not its ``process`` one, which every node publishes)
    cls_before = next((v for k, v in before.items() if k.startswith("classifier_node") and "descriptors" in v), {})
    cls_after = next((v for k, v in after.items() if k.startswith("classifier_node") and "descriptors" in v), {})
    for key in ("descriptors", "predictions"):
        end = _int(cls_after, key)
        extra.classifier[key] = None if end is None else end - (_int(cls_before, key) or 0)
    drop = extra.link_drop
    if drop is not None:
        for p, hp in part_host.items():
            if hp != drop.host:
                continue
            drop.descriptors_missing[p] = extra.descriptor_gaps[p]
            drop.backlog[p], drop.recovered_after_s[p], drop.missing_after_recovery[p] = mh.link_drop_recovery(
                rows[p], drop.down_at, drop.up_at, WINDOW_HOP_S, WINDOW_LENGTH_S)
        drop.predictions_missing = extra.predictions.get(drop.host, {}).get("missing")


def _check_alive(procs: Any, t_start: float) -> None:
    """Raise when a node has exited (its last lines in the message)."""
    dead = [r for r in procs.nodes if r.returncode is not None]
    if dead:
        lines = "\n".join(dead[0].lines[-20:])
        raise RuntimeError(f"node {dead[0].spec.name} exited with {dead[0].returncode} after "
                           f"{time.monotonic() - t_start:.0f} s:\n{lines}")


def _memory_short(procs: Any, t_start: float) -> str | None:
    """Why the graph must stop now, when the machine is about to run out of memory (``None`` while it is not).

    The graph is stopped before the kernel kills a process, its own or anyone else's on a shared machine;
    the reason, with what the graph held, is the measured bound.
    """
    import psutil

    available = psutil.virtual_memory().available
    if available >= MEMORY_FLOOR_GB * 2**30:
        return None
    rss = 0
    for r in procs.nodes:
        try:
            rss += psutil.Process(r.process.pid).memory_info().rss
        except psutil.Error:
            pass
    return (f"stopped after {time.monotonic() - t_start:.0f} s: the machine had {available / 2**30:.1f} GB of "
            f"memory left (floor {MEMORY_FLOOR_GB:g} GB) and the graph's {len(procs.nodes)} processes held "
            f"{rss / 2**30:.1f} GB")


def _parts(monitor: _Monitor, before: dict[str, dict[str, str]], after: dict[str, dict[str, str]],
           runs: dict[str, range], t0: float, t1: float) -> list[PartResult]:
    """Per body part: counters over the measurement (``after`` less ``before``) and the windows of [t0, t1]."""
    with monitor.lock:
        windows = {k: list(v) for k, v in monitor.windows.items()}

    def status(diag: dict[str, dict[str, str]], test: Callable[[str], bool]) -> dict[str, str]:
        return next((v for k, v in diag.items() if test(k)), {})

    def delta(key: str, a: dict[str, str], b: dict[str, str]) -> int | None:
        end = _int(b, key)
        return None if end is None else end - (_int(a, key) or 0)

    samples_per_cell_s = cell_samples_per_s()
    out = []
    for part, ids in runs.items():
        r = PartResult(part, len(ids))
        is_window = lambda k, p=part: k.endswith(f"_{p}: windows")  # noqa: E731
        is_driver = lambda k, p=part: k.startswith("skin_driver") and k.endswith(f": {p}")  # noqa: E731
        w0, w1 = status(before, is_window), status(after, is_window)
        d0, d1 = status(before, is_driver), status(after, is_driver)
        r.messages_received = delta("messages_received", w0, w1)
        r.lost = {k.removeprefix("fault_"): delta(k, w0, w1) or 0 for k in LOST_KEYS}
        r.late = {k.removeprefix("fault_"): delta(k, w0, w1) or 0 for k in LATE_KEYS}
        r.messages_sent = delta("messages", d0, d1)
        r.bus_lost_frames = delta("lost_frames", d0, d1)
        samples = delta("samples", d0, d1)
        if samples is not None:
            r.driver_realtime_factor = round(samples / (len(ids) * samples_per_cell_s * (t1 - t0)), 4)
        rows = windows.get(part, [])
        r.windows, r.realtime_factor, r.lag_growth_s = _part_timing(rows, t0, t1)
        r.windows_expected = (t1 - t0) / WINDOW_HOP_S
        in_window = [c for t, _, c in rows if t0 <= t <= t1]
        r.cells_in_contact = min(in_window) if in_window else None
        out.append(r)
    return out


def format_scale_graph(report: ScaleGraphReport) -> str:
    """The report as text."""
    d = report.to_dict()
    lines = [f"scale graph: {d['n_cells']} skin cells in {d['body_parts']} body parts, "
             f"{'one driver' if report.one_driver else 'one driver per body part'}, one window node per body part "
             f"({len(report.processes)} processes), {WINDOW_LENGTH_S:g} s windows every {WINDOW_HOP_S:g} s, "
             f"groups {','.join(report.groups)}",
             f"measured {d['seconds']:.0f} s after a {d['warm_up_s']:.0f} s warm-up; {d['cpus']} CPUs, load "
             f"{d['load_avg_start'][0]:.1f} -> {d['load_avg_end'][0]:.1f}"
             + (f"; no descriptor yet from {len(report.silent_at_start)} body parts when the warm-up ended"
                if report.silent_at_start else ""),
             "CPU per cell: ms of CPU per cell and wall second, and per cell and second of data handled (the "
             "demand, also of a process that fell behind)",
             f"{'process':<26} {'cells':>6} {'CPU %':>7} {'ms/cell/s':>10} {'ms/cell/data s':>15} {'RSS MB':>7}"]

    def f(x: Any, fmt: str) -> str:
        return "-" if x is None else format(x, fmt)

    for p in report.processes:
        lines.append(f"{p.name:<26} {p.cells:>6} {f(p.cpu_percent, '7.1f')} {f(p.cpu_ms_per_cell_s, '10.3f')} "
                     f"{f(p.cpu_ms_per_cell_data_s, '15.3f')} {f(p.rss_mb, '7.0f')}")
    for exe, v in d["cpu_by_executable"].items():
        lines.append(f"{'all ' + exe:<26} {d['n_cells']:>6} {f(v['cpu_percent'], '7.1f')} "
                     f"{f(v['cpu_ms_per_cell_s'], '10.3f')} {f(v['cpu_ms_per_cell_data_s'], '15.3f')}")
    lines.append(f"{'body part':<12} {'sent':>8} {'received':>9} {'lost':>5} {'driver RTF':>10} {'windows':>8} "
                 f"{'expected':>9} {'RTF':>6} {'lag +s':>7} kept up")
    for name, p in d["parts"].items():
        lines.append(f"{name:<12} {f(p['messages_sent'], '8d')} {f(p['messages_received'], '9d')} "
                     f"{p['lost_frames']:>5d} {f(p['driver_realtime_factor'], '10.3f')} {p['windows']:>8d} "
                     f"{p['windows_expected']:>9.1f} "
                     f"{f(p['realtime_factor'], '6.3f')} {f(p['lag_growth_s'], '7.2f')} "
                     f"{'yes' if p['kept_up'] else 'NO'}")
    mh = d["multi_host"]
    if mh is not None:
        per_host = ", ".join(f"{h} {c} cells" for h, c in mh["cells_per_host"].items())
        lines.append(f"hosts: {mh['hosts']} body-part hosts ({per_host}) "
                     f"and the classifier's; discovery: {mh['discovery_how']}; a joining participant saw the graph in "
                     f"{f(mh['discovery_s'], '.3f')} s")
        lines.append(f"cross-host traffic: {f(mh['cross_host_bytes_per_s'], '.0f')} B/s, "
                     f"{f(mh['cross_host_bytes_per_cell_s'], '.2f')} B/s per cell, "
                     f"{f(mh['cross_host_bytes_per_part_s'], '.0f')} B/s per body part; per host (tx/rx B/s): "
                     + ", ".join(f"{h} {v['tx']:.0f}/{v['rx']:.0f}" for h, v in mh["traffic_per_host_bytes_per_s"].items()))
        lines.append(f"descriptors lost between hosts: {mh['descriptors_lost']}; predictions back: "
                     + ", ".join(f"{h} {v['received']} received, {v['missing']} missing of {v['sent']}"
                                 for h, v in mh["predictions"].items())
                     + f"; classifier took {mh['classifier'].get('descriptors')} descriptors and published "
                       f"{mh['classifier'].get('predictions')} predictions")
        if mh["link_drop"] is not None:
            ld = mh["link_drop"]
            lines.append(f"link drop: {ld['host']} down {ld['down_s']:.1f} s; descriptors missing "
                         f"{ld['descriptors_missing']}, backlog {ld['backlog']} (queue depth {ld['queue_depth']}), "
                         f"recovered after {ld['recovered_after_s']} s, predictions missing {ld['predictions_missing']}")
    if report.stopped:
        lines.append(f"the graph was {report.stopped}")
    for t in d["targets"].values():
        lines.append(f"target: {t['target']}: {'met' if t['met'] else 'NOT met'}")
    return "\n".join(lines)
