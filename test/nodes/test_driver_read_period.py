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
