"""The NAO graph through a stopped process (``kill -STOP``): a stall of its skin driver (8 s) or of its window
node (5 s).  The stopped time is a gap, counted and reported, never spliced into a window, and descriptors of
fresh data resume soon after the cause ends.

The graph runs as ``tactile launch nao`` starts it (simulated bus at real time, clock stamps), with fixed
windows so that descriptors come every hop whatever the scene does.  The tests wait on events (a descriptor,
a frames message, a diagnostics message); the stop itself is the only timed wait.

Driver stall: the simulated bus lives in the driver's process and was stopped with it: after ``SIGCONT`` it
simulates the 8 s it missed before the driver reads their newest 0.25 s (0.7 s of CPU per simulated 2 s of the
NAO scene), which a hardware bus does not.  The window node's recovery is therefore timed from the driver's
first message of data sampled after the stall.

Window-node stop: the driver goes on publishing; each frames topic queues ``qos.frames.depth`` messages
for the stopped node and loses the rest, which the node counts from the cells' batch numbers
(``lost_cell_batches``) when it runs again.
"""

from __future__ import annotations

import os
import random
import signal
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

STALL_S = 8.0
WINDOW_NODE_STOP_S = 5.0
#: The window node's frames queue in the stop test (messages per body-part topic; 256 as shipped).
QUEUE_DEPTH = 32
#: The fixed windows of these tests (short, so that the recovery is timed in windows).
LENGTH_S, HOP_S = 1.0, 0.25


def _stamp_s(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


@dataclass
class Probe:
    """What the probe node received, on the host clock, and the graph it watches."""

    procs: object
    specs: list
    spin_until: Callable[[Callable[[], object], float], bool]
    descs: list[tuple[float, float, float]] = field(default_factory=list)  # (arrival, window start, window end)
    diags: list[tuple[float, dict]] = field(default_factory=list)  # (arrival, the window node's values)
    statuses: dict[str, dict] = field(default_factory=dict)  # the newest values of every node's status, by name
    # (arrival, stamp, cell runs) of one body part's messages
    frames: list[tuple[float, float, int]] = field(default_factory=list)

    def parameter(self, executable: str, name: str):
        return next(s for s in self.specs if s.executable == executable).parameters[name]

    def pid(self, executable: str) -> int:
        return next(n for n in self.procs.nodes if n.spec.executable == executable).process.pid

    def stop(self, executable: str, seconds: float) -> tuple[float, float]:
        """``kill -STOP`` the node for ``seconds`` while the probe spins; return (stopped, resumed) host times."""
        pid = self.pid(executable)
        stopped = time.time()
        os.kill(pid, signal.SIGSTOP)
        try:
            self.spin_until(lambda: False, seconds)  # the stop itself
        finally:
            os.kill(pid, signal.SIGCONT)
        return stopped, time.time()

    def processes(self) -> dict[str, dict]:
        """The newest ``process`` status of every node that sent one, by node name."""
        return {name.rpartition(": ")[0].split("/")[-1]: v for name, v in self.statuses.items()
                if name.endswith(": process")}

    def all_reported(self) -> bool:
        """Whether every node of the graph has sent its ``process`` status (it is up)."""
        return {n.spec.name for n in self.procs.nodes} <= set(self.processes())

    def fresh(self, since: float) -> list[tuple[float, float, float]]:
        """Descriptors of windows that end after ``since`` - 1 s (data sampled after a stop)."""
        return [d for d in self.descs if d[2] > since - 1.0]

    def faults(self) -> dict[str, int]:
        return {k: int(v) for k, v in self.diags[-1][1].items() if k.startswith("fault_")}


@contextmanager
def nao_graph(tmp_path, **window_node: object) -> Iterator[Probe]:
    """The NAO graph with fixed windows (and ``window_node`` parameters) and a probe on its descriptors,
    diagnostics and left-hand frames."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, SkinPartFrames
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    specs = build_graph("nao", sim_scene="demo_nao", model_path=str(tmp_path / "model.json"),
                        overrides={"window_node": {"window.mode": "fixed", "window.length_s": LENGTH_S,
                                                   "window.hop_s": HOP_S, **window_node}})
    domain = random.randint(1, 100)
    env = localhost_environment()
    env["ROS_DOMAIN_ID"] = str(domain)
    procs = GraphProcesses(specs, env=env, output=None)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("stall_probe", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)

    def spin_until(cond, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and not cond() and not procs.exited():
            ex.spin_once(timeout_sec=0.05)
        return bool(cond())

    probe = Probe(procs, specs, spin_until)

    def on_diag(msg) -> None:
        for st in msg.status:
            probe.statuses[st.name] = {kv.key: kv.value for kv in st.values}
            if st.name.endswith("window_node: windows"):
                probe.diags.append((time.time(), {kv.key: kv.value for kv in st.values}))

    node.create_subscription(Descriptor, "tactile/descriptor",
                             lambda m: probe.descs.append((time.time(), _stamp_s(m.window_start),
                                                           _stamp_s(m.window_end))),
                             QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 100)
    node.create_subscription(SkinPartFrames, "tactile/left_hand/frames",
                             lambda m: probe.frames.append((time.time(), _stamp_s(m.header.stamp),
                                                            len(m.sequence))), 1000)
    ex.add_node(node)
    procs.start()
    try:
        assert spin_until(lambda: len(probe.descs) >= 4, 120.0), [n.lines[-5:] for n in procs.nodes]
        yield probe
    finally:
        procs.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_an_8_s_driver_stall_is_a_gap_and_descriptors_resume_within_2_s(tmp_path):
    with nao_graph(tmp_path) as g:
        n_diag = len(g.diags)
        stopped, resumed = g.stop("skin_driver", STALL_S)  # the window node must keep reporting meanwhile
        during = [values for t, values in g.diags[n_diag:] if stopped + 1.0 < t < resumed]
        assert len(during) >= 3, "the window node's diagnostics went silent during the stall"
        fresh_frames = lambda: [t for t, stamp, _ in g.frames if stamp > resumed - 1.0]  # noqa: E731
        # both: the executor may run the descriptor's callback before that of the frames it was made from
        assert g.spin_until(lambda: g.fresh(resumed) and fresh_frames(), 30.0), (
            f"after the stall: {len(g.fresh(resumed))} descriptors and {len(fresh_frames())} frames messages of "
            "fresh data")
        first_fresh = g.fresh(resumed)[0]
        back = min(fresh_frames())  # the driver's first data after the stall
        assert first_fresh[0] - back <= 2.0, (
            f"descriptors resumed {first_fresh[0] - back:.2f} s after the driver's first fresh data "
            f"({first_fresh[0] - resumed:.2f} s after SIGCONT)")
        # the stall is a gap: the windows inside it are counted, not described; those across its edges
        # hold the samples around it and are flagged (windower gap)
        assert not [d for d in g.descs if d[1] > stopped + 1.0 and d[2] < resumed - 1.0]
        assert g.spin_until(lambda: g.diags and g.diags[-1][0] > first_fresh[0] + 1.0, 10.0)
        faults = g.faults()
        assert faults.get("fault_windower_windows_without_samples", 0) >= 1, faults
        assert faults.get("fault_windower_gap", 0) >= 1, faults
        # the driver saw the stall as the time between two reads of its bus
        assert g.spin_until(lambda: any(float(v.get("read_gap_max_ms", 0)) > 0.0 and name.endswith(": bus")
                                        and int(v.get("read_gaps_long", 0)) >= 1
                                        for name, v in g.statuses.items()), 10.0), g.statuses
        bus = [v for name, v in g.statuses.items() if name.endswith(": bus")]
        assert max(float(v["read_gap_max_ms"]) for v in bus) >= 1e3 * STALL_S, bus
        # every node settled its start-up heap (frozen: no full collection scans it) and reports its pauses
        processes = g.processes()
        assert g.all_reported(), sorted(processes)
        assert all(int(v["gc_frozen"]) > 10_000 and float(v["gc_settle_ms"]) > 0 for v in processes.values()), processes


def test_a_5_s_window_node_stop_is_counted_and_fresh_windows_resume_within_a_window(tmp_path):
    from tactile_descriptors_ros.core.robot import load_robot

    n_cells = sum(len(p.cells) for p in load_robot("nao").body_parts)
    # a short queue: even a driver slowed by a loaded machine (fewer, fuller messages) overflows it in the stop
    with nao_graph(tmp_path, **{"qos.frames.depth": QUEUE_DEPTH}) as g:
        # every node of the graph up (its process status seen), so that no participant starts during the stop
        assert g.spin_until(lambda: g.diags and g.all_reported(), 30.0), f"not every node reported: {sorted(g.statuses)}"
        before = g.faults()
        stopped, resumed = g.stop("window_node", WINDOW_NODE_STOP_S)
        # a whole window of data sampled after SIGCONT: ends one window and at most one hop later, is then
        # cut, described and published; the node has first the queued messages to take
        whole = lambda: [d for d in g.descs if d[1] >= resumed]  # noqa: E731
        after_stop = lambda: [(round(t - resumed, 2), v.get("frames_messages_taken"),  # noqa: E731
                               v.get("descriptors_published")) for t, v in g.diags if t > resumed]
        if not g.spin_until(whole, 30.0):
            taken = {v for _, v, _ in after_stop()}
            if len(taken) == 1 and len(after_stop()) >= 20 and [f for f in g.frames if f[0] > resumed + 20.0]:
                # the node runs (its diagnostics every second) but takes no frames message for 20 s after the stop
                # while the driver publishes them: nothing reaches its subscriptions any more (docs/nodes.md: seen
                # three times, not reproduced in 24 runs here); not the windowing this test is about
                pytest.xfail(f"no frames delivered to the window node after its stop (frames messages taken "
                             f"stayed {taken}; publishers it matched on left_hand: "
                             f"{g.diags[-1][1].get('left_hand_publishers')}); docs/nodes.md, a node stopped for seconds")
        assert whole(), (
            f"no window of fresh data after the stop: {g.descs[-3:]}; the window node's (s after, frames messages, "
            f"descriptors) since: {after_stop()[-5:]}; its last status: {g.diags[-1][1]}")
        late_s = whole()[0][0] - whole()[0][2]
        assert whole()[0][2] <= resumed + LENGTH_S + HOP_S + 1e-3, whole()[0]
        assert late_s <= LENGTH_S, f"the first fresh window came {late_s:.2f} s after its end"
        # what the topics could not queue is counted: on the left hand's topic alone, every cell run the probe
        # saw published during the stop but the last queue depth of messages (the driver's own rate, which a
        # loaded machine lowers, and its messages, which it fills fuller); the windows of the part of the stop
        # that no topic queued are counted empty, not described
        assert g.spin_until(lambda: g.diags[-1][0] > whole()[0][0], 10.0)
        after = g.faults()
        lost = after.get("fault_lost_cell_batches", 0) - before.get("fault_lost_cell_batches", 0)
        depth = g.parameter("window_node", "qos.frames.depth")
        during = [runs for t, _, runs in g.frames if stopped + 0.2 < t < resumed]
        left_hand_lost = sum(during[:-depth]) if len(during) > depth else 0
        batch_s = g.parameter("skin_driver", "batch_s")
        assert left_hand_lost > 0, f"the driver published {len(during)} left-hand messages in the stop"
        assert left_hand_lost <= lost <= n_cells * (WINDOW_NODE_STOP_S + 1.0) / batch_s, (
            lost, left_hand_lost, g.faults())
        empty = (after.get("fault_windower_windows_without_samples", 0)
                 - before.get("fault_windower_windows_without_samples", 0))
        assert empty >= 1, after
