"""The NAO graph through an 8 s stall of its skin driver (``kill -STOP``): the window node keeps reporting,
the stall is a gap (never spliced into a window), and descriptors resume within 2 s of the driver's first
message of fresh data.

The graph runs as ``tactile launch nao`` starts it (simulated bus at real time, clock stamps), with fixed
windows so that descriptors come every hop whatever the scene does.  The simulated bus lives in the
driver's process and was stopped with it: after ``SIGCONT`` it simulates the 8 s it missed before the
driver reads their newest 0.25 s (0.7 s of CPU per simulated 2 s of the NAO scene), which a hardware bus
does not.  The window node's recovery is therefore timed from the driver's first message of data sampled
after the stall.  The test waits on events (a descriptor, a frames message, a diagnostics message); the
8 s are the stall itself.
"""

from __future__ import annotations

import os
import random
import signal
import time

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

STALL_S = 8.0


def _stamp_s(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def test_an_8_s_driver_stall_is_a_gap_and_descriptors_resume_within_2_s(tmp_path):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, SkinPartFrames
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    specs = build_graph("nao", sim_scene="demo_nao", model_path=str(tmp_path / "model.json"),
                        overrides={"window_node": {"window.mode": "fixed", "window.length_s": 1.0,
                                                   "window.hop_s": 0.25}})
    domain = random.randint(1, 100)
    env = localhost_environment()
    env["ROS_DOMAIN_ID"] = str(domain)
    procs = GraphProcesses(specs, env=env, output=None)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("stall_probe", context=ctx)
    descs: list[tuple[float, float, float]] = []  # (arrival, window start, window end) on the host clock
    diags: list[tuple[float, dict]] = []  # (arrival, the window node's values)

    def on_desc(msg) -> None:
        descs.append((time.time(), _stamp_s(msg.window_start), _stamp_s(msg.window_end)))

    def on_diag(msg) -> None:
        for st in msg.status:
            if st.name.endswith("window_node: windows"):
                diags.append((time.time(), {kv.key: kv.value for kv in st.values}))

    node.create_subscription(Descriptor, "tactile/descriptor", on_desc,
                             QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 100)
    frames: list[tuple[float, float]] = []  # (arrival, stamp) of one body part's messages

    def on_frames(msg) -> None:
        frames.append((time.time(), _stamp_s(msg.header.stamp)))

    node.create_subscription(SkinPartFrames, "tactile/left_hand/frames", on_frames, 1000)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)

    def spin_until(cond, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and not cond() and not procs.exited():
            ex.spin_once(timeout_sec=0.05)
        return bool(cond())

    procs.start()
    try:
        assert spin_until(lambda: len(descs) >= 4, 120.0), [n.lines[-5:] for n in procs.nodes]
        driver = next(n for n in procs.nodes if n.spec.executable == "skin_driver")
        n_diag = len(diags)
        stopped = time.time()
        os.kill(driver.process.pid, signal.SIGSTOP)
        try:
            spin_until(lambda: False, STALL_S)  # the stall: the window node must keep reporting
        finally:
            os.kill(driver.process.pid, signal.SIGCONT)
        resumed = time.time()
        during = [values for t, values in diags[n_diag:] if stopped + 1.0 < t < resumed]
        assert len(during) >= 3, "the window node's diagnostics went silent during the stall"
        fresh = lambda: [d for d in descs if d[2] > resumed - 1.0]  # noqa: E731  windows of data after the stall
        fresh_frames = lambda: [t for t, stamp in frames if stamp > resumed - 1.0]  # noqa: E731
        # both: the executor may run the descriptor's callback before that of the frames it was made from
        assert spin_until(lambda: fresh() and fresh_frames(), 30.0), (
            f"after the stall: {len(fresh())} descriptors and {len(fresh_frames())} frames messages of fresh data")
        first_fresh = fresh()[0]
        back = min(fresh_frames())  # the driver's first data after the stall
        assert first_fresh[0] - back <= 2.0, (
            f"descriptors resumed {first_fresh[0] - back:.2f} s after the driver's first fresh data "
            f"({first_fresh[0] - resumed:.2f} s after SIGCONT)")
        # the stall is a gap: the windows inside it are counted, not described; those across its edges
        # hold the samples around it and are flagged (windower gap)
        assert not [d for d in descs if d[1] > stopped + 1.0 and d[2] < resumed - 1.0]
        assert spin_until(lambda: diags and diags[-1][0] > first_fresh[0] + 1.0, 10.0)
        values = diags[-1][1]
        faults = {k: v for k, v in values.items() if k.startswith("fault_")}
        assert int(values.get("fault_windower_windows_without_samples", "0")) >= 1, faults
        assert int(values.get("fault_windower_gap", "0")) >= 1, faults
    finally:
        procs.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
