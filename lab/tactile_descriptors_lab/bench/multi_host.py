"""The scale graph across hosts: placement, rclpy on a host, traffic, discovery and a dropped link.

``tactile bench --scale-graph --hosts H`` runs the scale graph
(:mod:`.scale_graph`) on ``H`` body-part hosts and one classifier host, each
a network namespace of :class:`~.netns.VirtualHosts`: every body part's
driver and window node on the host its body part is placed on (body parts
split into ``H`` consecutive runs), the classifier on its own host, the
bench's observers on the classifier's host (descriptors, diagnostics,
predictions) and a listener process on every body-part host (the
predictions that come back: :class:`PredictionListener`).

Discovery is DDS's simple discovery with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``
and a multicast route on each host's link: the namespaces' only links are
the bench's own, so announcements cannot leave the machine, and no process
has to be started first or be told any address (static peers would be a
list of addresses per host).  ``discovery="server"`` runs Fast DDS's
discovery server on the classifier's host instead (:class:`DiscoveryServer`),
whose traffic grows with the participants rather than faster.  The bench
process itself stays in this machine's namespace: each observer on the
classifier's host is an rclpy context created by a thread that entered the
host's namespace (:func:`~.netns.enter_namespace`), so its DDS participant
and threads live on that host.

What this module measures beside the scale graph's figures:

* **traffic**: each host link's kernel counters over the measurement
  (:meth:`~.netns.VirtualHosts.counters`), bytes per second and per cell;
* **discovery**: a participant joining the running graph on the classifier's
  host, from its creation until it sees every node and every window node's
  descriptor publisher (:func:`discovery_time`);
* **descriptors lost on the way**: gaps in each body part's window end
  stamps (fixed windows end one hop apart: :func:`descriptor_gaps`);
* **predictions back**: predictions received on each body-part host against
  those the classifier's host received (:func:`missing_predictions`);
* **a link drop**: a body-part host's cable pulled for some seconds during
  the measurement; the descriptors and predictions lost are counted, the
  backlog delivered when the link returns is bounded by the descriptor
  QoS depth, and the graph has recovered when that host's descriptors
  arrive with their usual lag again (:func:`link_drop_recovery`).
"""

from __future__ import annotations

import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "CLASSIFIER_HOST",
    "RosThread",
    "host_names",
    "assign_parts",
    "node_hosts",
    "descriptor_gaps",
    "missing_predictions",
    "LinkDrop",
    "link_drop_recovery",
    "discovery_time",
    "PredictionLog",
    "PredictionListener",
    "listen_predictions",
    "MultiHostResult",
    "DiscoveryServer",
    "DISCOVERY_MODES",
    "discovery_env",
]

#: Name of the classifier's host.
CLASSIFIER_HOST = "classifier"
#: Longest wait for an observer's rclpy context to come up [s].
ROS_THREAD_START_S = 60.0
_RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
_SERVER = "ROS_DISCOVERY_SERVER"
#: Discovery modes across hosts: DDS's simple discovery (multicast), or a Fast DDS discovery server.
DISCOVERY_MODES = ("subnet", "server")
#: UDP port of the discovery server (Fast DDS's default).
DISCOVERY_SERVER_PORT = 11811


def discovery_env(mode: str, server_address: str | None = None) -> dict[str, str]:
    """The environment of every participant on the hosts for a discovery ``mode`` of :data:`DISCOVERY_MODES`."""
    if mode not in DISCOVERY_MODES:
        raise ValueError(f"discovery must be one of {DISCOVERY_MODES}, got {mode!r}")
    env = {_RANGE: "SUBNET"}
    if mode == "server":
        if not server_address:
            raise ValueError("a discovery server needs its address")
        env[_SERVER] = f"{server_address}:{DISCOVERY_SERVER_PORT}"
    return env


class DiscoveryServer:
    """Fast DDS's discovery server (``fast-discovery-server``, shipped in the wheels) on a host.

    Participants started with ``ROS_DISCOVERY_SERVER=<address>:11811`` are its
    clients: each announces itself to the server only, and the server
    forwards what each needs (those sharing a topic), so the traffic and the
    state grow with the participants, not with their square.
    """

    def __init__(self, prefix: Sequence[str], address: str, env: dict[str, str]) -> None:
        import shutil
        import subprocess
        import sys

        exe = shutil.which("fast-discovery-server", path=os.path.join(sys.prefix, "bin")) \
            or shutil.which("fast-discovery-server")
        if exe is None:
            raise RuntimeError("fast-discovery-server not found (it ships in the ros-fastdds wheel)")
        # 42: the tool's "plain server" command, as `fastdds discovery -l ADDRESS -p PORT` runs it
        self.process = subprocess.Popen([*prefix, exe, "42", "-i", "0", "-l", address, "-p",
                                         str(DISCOVERY_SERVER_PORT)], env=env, text=True, bufsize=1,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        start_new_session=True)
        first = self.process.stdout.readline() if self.process.stdout else ""
        if "started" not in first.lower():
            self.stop()
            raise RuntimeError(f"the discovery server did not start: {first.strip()!r}")

    def stop(self) -> None:
        import signal
        import subprocess

        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.communicate(timeout=10.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.communicate()
        elif self.process.stdout is not None:
            self.process.stdout.close()
_INIT_LOCK = threading.Lock()


def host_names(hosts: int) -> list[str]:
    """Body-part hosts ``host0 .. host<H-1>`` and the classifier's host, in that order."""
    if hosts < 1:
        raise ValueError(f"need at least one body-part host, got {hosts}")
    return [f"host{k}" for k in range(hosts)] + [CLASSIFIER_HOST]


def assign_parts(parts: Sequence[str], hosts: int) -> dict[str, str]:
    """Body part -> host: ``hosts`` consecutive runs of body parts whose sizes differ by at most one."""
    if not 1 <= hosts <= len(parts):
        raise ValueError(f"{len(parts)} body parts cannot be split over {hosts} hosts (1 to {len(parts)})")
    base, extra = divmod(len(parts), hosts)
    out, k = {}, 0
    for h, name in enumerate(host_names(hosts)[:-1]):
        for part in parts[k:k + base + (1 if h < extra else 0)]:
            out[part] = name
        k += base + (1 if h < extra else 0)
    return out


def node_hosts(specs: Iterable[Any], part_host: dict[str, str]) -> dict[str, str]:
    """Node name -> host: a node of body parts on their host (all on one), every other node on the classifier's.

    Raises
    ------
    ValueError
        For a node whose body parts are placed on different hosts.
    """
    out = {}
    for s in specs:
        parts = list(s.parameters.get("body_parts") or [])
        hosts = {part_host[p] for p in parts}
        if len(hosts) > 1:
            raise ValueError(f"node {s.name} serves body parts on {len(hosts)} hosts: {sorted(hosts)}")
        out[s.name] = hosts.pop() if hosts else CLASSIFIER_HOST
    return out


# ----------------------------------------------------------------- rclpy on a host
class RosThread:
    """An rclpy context, node and executor in a thread of their own, optionally inside a network namespace.

    The thread enters ``namespace`` first (so the DDS participant and its
    threads live on that host), creates the node, calls ``setup(node)``
    (create subscriptions there; its result is :attr:`value`) and spins
    until :meth:`stop`.  In a namespace the context discovers as ``env``
    says (default: ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``, since its
    host's only link is the bench's own), elsewhere with ``LOCALHOST``: rcl
    and Fast DDS read these variables when the context and its participant
    are made, so they are set for those calls only, under a lock that every
    :class:`RosThread` takes.
    """

    def __init__(self, name: str, setup: Callable[[Any], Any], namespace: str | None = None,
                 env: dict[str, str] | None = None) -> None:
        if namespace is None and env:
            raise ValueError("discovery settings apply only inside a host's namespace")
        self.env = dict(env or {_RANGE: "SUBNET"}) if namespace is not None else {_RANGE: "LOCALHOST"}
        self.name = name
        self.namespace = namespace
        self._setup = setup
        self.value: Any = None
        self.node: Any = None
        self.error: BaseException | None = None
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"ros-{name}")

    def start(self) -> RosThread:
        self._thread.start()
        if not self._ready.wait(ROS_THREAD_START_S):
            raise RuntimeError(f"rclpy context {self.name} did not come up in {ROS_THREAD_START_S:g} s")
        if self.error is not None:
            raise RuntimeError(f"rclpy context {self.name} failed: {self.error!r}") from self.error
        return self

    def _run(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        context = ex = None
        try:
            if self.namespace is not None:
                from .netns import enter_namespace

                enter_namespace(self.namespace)
            context = rclpy.Context()
            with _INIT_LOCK:
                before = {k: os.environ.get(k) for k in (*self.env, _SERVER)}
                os.environ.pop(_SERVER, None)
                os.environ.update(self.env)
                try:
                    rclpy.init(context=context)
                    self.node = rclpy.create_node(self.name, context=context)
                finally:
                    for k, v in before.items():
                        if v is None:
                            os.environ.pop(k, None)
                        else:
                            os.environ[k] = v
            self.value = self._setup(self.node)
            ex = SingleThreadedExecutor(context=context)
            ex.add_node(self.node)
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self.error = exc
            self._ready.set()
            self._shutdown(context, ex)
            return
        self._ready.set()
        try:
            while not self._stop.is_set() and context.ok():
                ex.spin_once(timeout_sec=0.1)
        finally:
            self._shutdown(context, ex)

    def _shutdown(self, context: Any, ex: Any) -> None:
        import rclpy

        if ex is not None:
            ex.shutdown()
        if self.node is not None:
            self.node.destroy_node()
        if context is not None and context.ok():
            rclpy.shutdown(context=context)

    def stop(self, timeout_s: float = 10.0) -> None:
        self._stop.set()
        self._thread.join(timeout=timeout_s)


@dataclass
class PredictionLog:
    """Predictions a host received: (arrival monotonic time, window end stamp [ns])."""

    rows: list[tuple[float, int]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)
    #: serialized bytes of the predictions received (counted by :meth:`subscribe`'s callback)
    bytes_received: int = 0

    def payload_bytes(self) -> int:
        with self.lock:
            return self.bytes_received

    def subscribe(self, node: Any) -> PredictionLog:
        from rclpy.serialization import serialize_message

        from tactile_descriptors_msgs.msg import Prediction
        from tactile_descriptors_ros.nodes.qos import qos_profile
        from tactile_descriptors_ros.topics import PREDICTION_TOPIC, absolute

        def on_prediction(msg: Any) -> None:
            end = msg.window_end.sec * 1_000_000_000 + msg.window_end.nanosec
            size = len(serialize_message(msg))
            with self.lock:
                self.rows.append((time.monotonic(), end))
                self.bytes_received += size

        node.create_subscription(Prediction, absolute(PREDICTION_TOPIC), on_prediction,
                                 qos_profile("reliable", "volatile", 50, "prediction"))
        return self

    def ends(self, until: float | None = None, since: float | None = None) -> Counter[int]:
        """Window end stamps of the predictions received (from monotonic time ``since`` up to ``until``), with
        multiplicity."""
        with self.lock:
            return Counter(e for t, e in self.rows
                           if (until is None or t <= until) and (since is None or t >= since))


class PredictionListener:
    """A process on a host that logs the predictions it receives (:func:`listen_predictions` on its stdout).

    One process per host, not an rclpy context in the bench process: Fast
    DDS computes a participant's host identity once per process (from the
    addresses it sees first), so participants of one process on several
    hosts would take each other for neighbours on one machine.
    """

    def __init__(self, prefix: Sequence[str], env: dict[str, str]) -> None:
        import subprocess
        import sys

        self.log = PredictionLog()
        self._ready = threading.Event()
        self.lines: list[str] = []
        self.process = subprocess.Popen([*prefix, sys.executable, "-m", __name__], env=env, text=True, bufsize=1,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        start_new_session=True)
        self._reader = threading.Thread(target=self._read, daemon=True, name="prediction-listener")
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            parts = line.split()
            if len(parts) == 3 and parts[0] == "P":
                with self.log.lock:
                    self.log.rows.append((float(parts[1]), int(parts[2])))
            elif line.strip() == "ready":
                self._ready.set()
            else:
                self.lines = (self.lines + [line.rstrip()])[-20:]
        self._ready.set()

    def wait_ready(self, timeout_s: float = ROS_THREAD_START_S) -> None:
        if not self._ready.wait(timeout_s) or self.process.poll() is not None:
            raise RuntimeError("the prediction listener did not start:\n" + "\n".join(self.lines))

    def stop(self) -> None:
        import signal
        import subprocess

        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(10.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._reader.join(timeout=5.0)
        if self.process.stdout is not None:
            self.process.stdout.close()


def listen_predictions() -> int:
    """Print ``P <monotonic s> <window end ns>`` for every prediction received, ``ready`` once subscribed."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init()
    node = rclpy.create_node(f"tactile_prediction_listener_{os.getpid()}")
    log = PredictionLog()

    def on_row() -> None:
        with log.lock:
            rows, log.rows[:] = list(log.rows), []
        for t, e in rows:
            print(f"P {t:.6f} {e}", flush=True)

    log.subscribe(node)
    node.create_timer(0.05, on_row)
    print("ready", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        on_row()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


def missing_predictions(sent: Counter[int], received: Counter[int]) -> int:
    """Predictions in ``sent`` (by window end, with multiplicity) that ``received`` lacks."""
    return int(sum(max(0, n - received.get(end, 0)) for end, n in sent.items()))


# ----------------------------------------------------------------- discovery
def discovery_time(namespace: str | None, nodes: Sequence[str], descriptor_publishers: int,
                   timeout_s: float = 40.0, env: dict[str, str] | None = None) -> float | None:
    """Seconds a new participant on ``namespace`` takes to see every node and descriptor publisher of the graph.

    From the creation of its node (its DDS participant already up) until
    ``get_node_names`` lists every name of ``nodes`` and the descriptor topic
    has ``descriptor_publishers`` publishers; ``None`` after ``timeout_s``.
    The probe subscribes to the descriptors, as the classifier does (a
    discovery server tells a client only of the endpoints on its topics).
    """
    from tactile_descriptors_msgs.msg import Descriptor
    from tactile_descriptors_ros.topics import DESCRIPTOR_TOPIC, absolute

    found: dict[str, float | None] = {}

    def setup(node: Any) -> None:
        t0 = time.monotonic()
        node.create_subscription(Descriptor, absolute(DESCRIPTOR_TOPIC), lambda msg: None, 10)
        want = set(nodes)
        while time.monotonic() - t0 < timeout_s:
            if want <= set(node.get_node_names()) and \
                    node.count_publishers(absolute(DESCRIPTOR_TOPIC)) >= descriptor_publishers:
                found["s"] = time.monotonic() - t0
                return
            time.sleep(0.005)
        found["s"] = None

    probe = RosThread(f"tactile_discovery_probe_{int(time.monotonic() * 1000) % 100000}", setup, namespace,
                      env=env)
    try:
        probe.start()  # setup() runs inside start's wait: the probe polls the graph before it spins
    finally:
        probe.stop()
    return found.get("s")


# ------------------------------------------------------------------ descriptors
def descriptor_gaps(ends_ns: Sequence[int], hop_ns: int) -> int:
    """Windows missing from a body part's fixed-window descriptors (end stamps a whole hop apart, in order)."""
    e = np.unique(np.asarray(ends_ns, dtype=np.int64))
    if e.size < 2:
        return 0
    steps = np.rint(np.diff(e) / float(hop_ns)).astype(np.int64)
    return int(np.sum(np.maximum(steps - 1, 0)))


@dataclass
class LinkDrop:
    """A host's link taken down for a while during the measurement, and what it did to the graph."""

    host: str
    down_at: float
    up_at: float
    #: per body part of the host: windows missing at the classifier's host (gaps in the end stamps)
    descriptors_missing: dict[str, int] = field(default_factory=dict)
    #: per body part: descriptors that arrived late after the link returned (the reliable writer's backlog)
    backlog: dict[str, int] = field(default_factory=dict)
    #: per body part: seconds from the link's return to the first descriptor with its usual lag again
    recovered_after_s: dict[str, float | None] = field(default_factory=dict)
    predictions_missing: int | None = None
    #: per body part: windows missing that were due one window or more after the link returned
    missing_after_recovery: dict[str, int] = field(default_factory=dict)
    #: the descriptor QoS depth: what bounds the backlog
    queue_depth: int = 10

    @property
    def down_s(self) -> float:
        return self.up_at - self.down_at

    def recovered_within(self, limit_s: float) -> bool:
        times = list(self.recovered_after_s.values())
        return bool(times) and all(t is not None and t <= limit_s for t in times)

    def to_dict(self) -> dict[str, Any]:
        return {"host": self.host, "down_s": round(self.down_s, 3),
                "descriptors_missing": self.descriptors_missing, "backlog": self.backlog,
                "queue_depth": self.queue_depth, "recovered_after_s": self.recovered_after_s,
                "missing_after_recovery": self.missing_after_recovery,
                "predictions_missing": self.predictions_missing}


def link_drop_recovery(rows: Sequence[tuple[float, int]], down_at: float, up_at: float, hop_s: float,
                       grace_s: float) -> tuple[int, float | None, int]:
    """A body part's descriptors around a link drop: (backlog, seconds to recover, windows lost after the grace).

    ``rows`` are (arrival monotonic time, window end stamp [ns]).  The usual
    lag (arrival minus end, whatever the clocks' offset) is the median over
    the descriptors that arrived before the drop; a window is *due* at its
    end plus the usual lag.  A descriptor due before ``up_at`` that arrived
    after it, more than a hop late, is backlog (what the writer kept while
    the link was down; at most its queue depth), and the part has recovered
    at the arrival of the first descriptor within a hop of its due time.  The third figure counts the windows missing
    (gaps in the end stamps) that were due ``grace_s`` or more after the
    link returned: a graph that recovers within ``grace_s`` loses none.
    """
    before = [t - e * 1e-9 for t, e in rows if t < down_at]
    if not before:
        return 0, None, 0
    usual = float(np.median(before))
    backlog, recovered = 0, None
    for t, e in sorted(rows, key=lambda r: r[0]):
        if t < up_at:
            continue
        due = e * 1e-9 + usual
        if due < up_at and t - due > hop_s:  # due while the link was down, delivered after it returned
            backlog += 1
        elif t - due <= hop_s and recovered is None:
            recovered = round(t - up_at, 3)
    ends = np.unique(np.asarray([e for _, e in rows], dtype=np.int64))
    hop_ns = int(round(hop_s * 1e9))
    lost_late = 0
    for a, b in zip(ends[:-1], ends[1:]):
        for k in range(1, int(round((b - a) / hop_ns))):
            if (a + k * hop_ns) * 1e-9 + usual >= up_at + grace_s:
                lost_late += 1
    return backlog, recovered, lost_late


# ------------------------------------------------------------------ the report
@dataclass
class MultiHostResult:
    """What the scale graph measured across hosts (``multi_host`` of its report)."""

    hosts: int
    #: how the participants find each other: a mode of :data:`DISCOVERY_MODES`
    discovery: str = "subnet"
    #: node name -> host
    placement: dict[str, str] = field(default_factory=dict)
    #: body part -> host
    part_hosts: dict[str, str] = field(default_factory=dict)
    cells_per_host: dict[str, int] = field(default_factory=dict)
    n_cells: int = 0
    seconds: float = 0.0
    #: seconds a participant joining on the classifier's host took to see the whole graph
    discovery_s: float | None = None
    #: host -> its link's counters from its creation to the measurement (discovery, start-up, warm-up)
    start_up_traffic: dict[str, dict[str, int]] = field(default_factory=dict)
    #: host -> its link's counters over the measurement
    traffic: dict[str, dict[str, int]] = field(default_factory=dict)
    #: body part -> windows missing from its descriptors at the classifier's host
    descriptor_gaps: dict[str, int] = field(default_factory=dict)
    #: body-part host -> predictions sent (seen on the classifier's host), received there, missing
    predictions: dict[str, dict[str, int]] = field(default_factory=dict)
    #: serialized bytes over the measurement: descriptors and diagnostics that reached the classifier's host from
    #: the body-part hosts, and predictions (one copy; each body-part host gets one)
    payload: dict[str, int] = field(default_factory=dict)
    #: the classifier's counters over the measurement: descriptors taken, predictions published
    classifier: dict[str, int | None] = field(default_factory=dict)
    link_drop: LinkDrop | None = None

    @property
    def cross_host_bytes_per_s(self) -> float | None:
        """Bytes per second sent onto the links by all hosts (each byte counted once, at its sender)."""
        if not self.traffic or not self.seconds:
            return None
        return sum(v["tx_bytes"] for v in self.traffic.values()) / self.seconds

    @property
    def cross_host_bytes_per_cell_s(self) -> float | None:
        total = self.cross_host_bytes_per_s
        return None if total is None or not self.n_cells else total / self.n_cells

    @property
    def cross_host_bytes_per_part_s(self) -> float | None:
        """Bytes per second sent onto the links per body part (what crosses is per body part, not per cell)."""
        total = self.cross_host_bytes_per_s
        return None if total is None or not self.part_hosts else total / len(self.part_hosts)

    @property
    def descriptors_lost(self) -> int:
        return int(sum(self.descriptor_gaps.values()))

    @property
    def predictions_missing(self) -> int:
        return int(sum(v["missing"] for v in self.predictions.values()))

    def to_dict(self) -> dict[str, Any]:
        per_s = self.cross_host_bytes_per_s
        per_cell = self.cross_host_bytes_per_cell_s
        return {
            "hosts": self.hosts, "placement": self.placement, "cells_per_host": self.cells_per_host,
            "discovery": self.discovery,
            "discovery_how": "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, multicast on the hosts' links"
            if self.discovery == "subnet" else "a Fast DDS discovery server on the classifier's host "
                                               "(ROS_DISCOVERY_SERVER)",
            "discovery_s": None if self.discovery_s is None else round(self.discovery_s, 3),
            "start_up_traffic": self.start_up_traffic, "traffic": self.traffic,
            "cross_host_bytes_per_s": None if per_s is None else round(per_s, 1),
            "cross_host_bytes_per_cell_s": None if per_cell is None else round(per_cell, 3),
            "cross_host_bytes_per_part_s": None if self.cross_host_bytes_per_part_s is None
            else round(self.cross_host_bytes_per_part_s, 1),
            "traffic_per_host_bytes_per_s": {h: {"tx": round(v["tx_bytes"] / self.seconds, 1),
                                                 "rx": round(v["rx_bytes"] / self.seconds, 1)}
                                             for h, v in self.traffic.items()} if self.seconds else {},
            "descriptor_gaps": self.descriptor_gaps, "descriptors_lost": self.descriptors_lost,
            "predictions": self.predictions, "predictions_missing": self.predictions_missing,
            "classifier": self.classifier,
            "payload_bytes_per_part_s": {k: round(v / self.seconds / max(1, len(self.part_hosts)), 1)
                                         for k, v in self.payload.items()} if self.seconds else {},
            "link_drop": None if self.link_drop is None else self.link_drop.to_dict(),
        }

    def placement_of_part(self, part: str) -> str | None:
        """The host of a body part."""
        return self.part_hosts.get(part)


if __name__ == "__main__":
    raise SystemExit(listen_predictions())
