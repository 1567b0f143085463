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


def test_a_reader_that_stops_reading_is_seen_in_the_longest_gap_between_reads(ros_context, tmp_path):
    """A handling that blocks the reader for 0.4 s once (a stalled thread, a long pause) shows in the bus status:
    ``read_gap_max_ms`` at least that long and one late read; before it, reads every period, none late."""
    import threading

    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.driver_base import READ_GAP_LONG_S
    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    robot = scale_robot_files(4, 1, tmp_path)
    scene = str(robot).replace(".yaml", "_part_0.scene.yaml")
    params = {"robot": str(robot), "transport": "simulated", "sim.scene": scene, "sim.loop": True,
              "stamp_source": "device", "tare_on_start_s": 0.0, "read_period_s": 0.02}
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
        # the gap ended after 20 reads at least one period apart and the stall, and before now
        assert 20 * 0.02 + stall_s <= float(values["read_gap_max_at_s"]) <= time.monotonic() - started
    finally:
        drv.close()
        ex.remove_node(drv)
        drv.destroy_node()
