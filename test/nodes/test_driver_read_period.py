"""The drivers' read_period_s: a device read at most once per period, its frames decoded together."""

from __future__ import annotations

import time

import pytest

from tactile_descriptors_ros.sim.synthetic import scale_robot_files

pytestmark = pytest.mark.ros


def _reads_over(ros_context, robot, scene, read_period_s: float, seconds: float = 1.5):
    """Reads, wall seconds and samples of a skin driver on a looped scene after it has read for a while."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    params = {"robot": str(robot), "transport": "simulated", "sim.scene": str(scene), "sim.loop": True,
              "stamp_source": "device", "tare_on_start_s": 0.0, "read_period_s": read_period_s}
    drv = SkinDriver(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    try:
        started = time.monotonic()
        while drv.reads == 0 and time.monotonic() - started < 60.0:  # the loop is simulated at configure
            ex.spin_once(timeout_sec=0.05)
        reads0, t0 = drv.reads, time.monotonic()
        while time.monotonic() - t0 < seconds:
            ex.spin_once(timeout_sec=0.05)
        return drv.reads - reads0, time.monotonic() - t0, sum(c.samples for c in drv.cells.values())
    finally:
        drv.close()
        ex.remove_node(drv)
        drv.destroy_node()


def test_a_read_period_bounds_how_often_the_device_is_read_and_loses_nothing(ros_context, tmp_path):
    robot = scale_robot_files(4, 1, tmp_path)
    scene = str(robot).replace(".yaml", "_part_0.scene.yaml")
    period = 0.1
    reads, wall_s, samples = _reads_over(ros_context, robot, scene, period)
    assert reads <= wall_s / period + 1  # never more often than the period, however fast frames come
    assert samples > 0
    eager, eager_wall_s, _ = _reads_over(ros_context, robot, scene, 0.0)
    assert eager / eager_wall_s > 2 * (reads / wall_s)  # without a period it reads as soon as frames are due


def test_a_reader_that_stops_reading_is_seen_in_the_longest_gap_between_reads(ros_context, tmp_path, monkeypatch):
    """A handling that blocks the reader for 0.4 s once (a stalled thread, a long pause) shows in the bus status:
    ``read_gap_max_ms`` at least that long and one late read; ``read_gap_max_at_s`` when the longest gap ended,
    after the first read, as the test's own clock saw the reads start."""
    import threading

    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.driver_base import READ_GAP_LONG_S
    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    robot = scale_robot_files(4, 1, tmp_path)
    scene = str(robot).replace(".yaml", "_part_0.scene.yaml")
    params = {"robot": str(robot), "transport": "simulated", "sim.scene": scene, "sim.loop": True,
              "stamp_source": "device", "tare_on_start_s": 0.0, "read_period_s": 0.02}
    read, read_starts = SkinDriver._read, []

    def timed_read(self):
        read_starts.append(time.monotonic())  # from the first read on: patched before the reader starts
        return read(self)

    monkeypatch.setattr(SkinDriver, "_read", timed_read)
    drv = SkinDriver(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    consume, stall_s, stalled = drv._consume, 0.4, threading.Event()

    def consume_then_stall(items):
        consume(items)
        if drv.reads == 20 and not stalled.is_set():
            time.sleep(stall_s)  # the fault under test: the reader thread does not read meanwhile
            stalled.set()

    drv._consume = consume_then_stall
    try:
        started = time.monotonic()
        while drv.reads < 30 and time.monotonic() - started < 60.0:
            ex.spin_once(timeout_sec=0.05)
        assert stalled.is_set() and drv.reads >= 30
        bus = next(s for s in drv.diagnostics.statuses() if s.name.endswith(": bus"))
        values = {kv.key: kv.value for kv in bus.values}
        assert float(values["read_gap_max_ms"]) >= 1e3 * stall_s
        assert int(values["read_gaps_long"]) >= 1
        assert READ_GAP_LONG_S < stall_s
        # when the longest gap ended: a read start of the test's clock, after a gap that long (a loaded machine
        # may make another gap than the stall the longest); its start right after the driver's clock read
        gap_s, at_s = float(values["read_gap_max_ms"]) / 1e3, float(values["read_gap_max_at_s"])
        starts = list(read_starts)
        ends = [(t - starts[0], t - before) for before, t in zip(starts, starts[1:])]
        tol_s = 0.05
        assert any(abs(end_s - at_s) <= tol_s and abs(gap - gap_s) <= tol_s for end_s, gap in ends), (
            at_s, gap_s, sorted(ends, key=lambda e: -e[1])[:3])
    finally:
        drv.close()
        ex.remove_node(drv)
        drv.destroy_node()
