"""The window node cuts a fixed window's samples before it closes and publishes the same bits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from node_helpers import left_hand_fixed_parameters, spin_until, window_nodes_side_by_side

pytestmark = pytest.mark.ros


def test_window_node_publishes_fixed_windows_cut_ahead_with_the_same_values(ros_context):
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg
    from tactile_descriptors_ros.streams.frames import SkinFrame
    from tactile_descriptors_ros.streams.skin_parts import SkinRun, pack_skin_part

    part = load_robot("nao").body_part("left_hand")
    common = left_hand_fixed_parameters()
    nodes, io, pub, out, ex = window_nodes_side_by_side(
        ros_context, common, {"ahead": [], "once": [Parameter("window.cut_ahead", value=False)]})
    ahead, once = nodes["ahead"], nodes["once"]

    rng = np.random.default_rng(5)
    t0 = 5_000_000_000
    n_batches = 160  # 1.6 s of 10 ms batches: the windows ending at 5.7485, 5.9985, 6.2485 and 6.4985 s
    for k in range(n_batches):
        start = t0 + k * 10_000_000
        off_a = np.arange(10, dtype=np.int64) * 1_000_000
        # force at 250 Hz on a grid of stamp time: 3 or 2 samples in a 10 ms batch
        off_f = np.arange((-(start - t0)) % 4_000_000, 10_000_000, 4_000_000, dtype=np.int64)
        runs = []
        for cell in part.cells:
            acc = np.clip(rng.normal(0, 12, (3, 10)) + [[0], [0], [256]], -512, 511).astype(np.int16)
            force = rng.integers(300, 700, (3, off_f.size)).astype(np.uint16)
            runs.append(SkinRun(cell.id, SkinFrame(start, acc, off_a, force, off_f, np.zeros(0, np.uint16),
                                                   sequence=k), np.zeros(3)))
        pub.publish(skin_part_to_msg(pack_skin_part("left_hand", runs, force_n_per_count=0.0024)))
        # taken one by one, as a node keeping up with its input takes them
        assert spin_until(ex, lambda n=k + 1: ahead.frames_taken == once.frames_taken == n, 10)
    assert spin_until(ex, lambda: len(out["desc_ahead"]) == len(out["desc_once"]) == 4, 20)
    assert ahead.cut_ahead and not once.cut_ahead
    # every window after the rehearsal closed from the samples cut ahead (the first may close before it)
    assert ahead.windower.heads["used"] >= 3 and ahead.windower.heads["recut"] == 0 and not once.windower.heads
    for a, b in zip(out["desc_ahead"], out["desc_once"]):
        assert (a.window_start, a.window_end) == (b.window_start, b.window_end)
        assert list(a.values) == list(b.values) and all(math.isfinite(v) for v in a.values)
    status = ahead._status().values
    assert status["cut_ahead_used"] == ahead.windower.heads["used"] and status["cut_ahead_n"] >= 3
    assert "cut_ahead_used" not in once._status().values
    for n in (ahead, once, io):
        n.destroy_node()
