"""The window node describes an exploration's window during its release time and publishes the same bits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from node_helpers import spin_until, window_nodes_side_by_side

pytestmark = pytest.mark.ros


def test_window_node_publishes_the_exploration_described_ahead_with_the_same_values(ros_context):
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg
    from tactile_descriptors_ros.streams.frames import SkinFrame
    from tactile_descriptors_ros.streams.skin_parts import SkinRun, pack_skin_part

    part = load_robot("nao").body_part("left_hand")
    common = [Parameter("robot", value="nao"), Parameter("body_parts", value=["left_hand"]),
              Parameter("window.mode", value="exploration"), Parameter("window.min_duration_s", value=0.5),
              Parameter("qos.frames.reliability", value="reliable"), Parameter("qos.frames.depth", value=2000)]
    nodes, io, pub, out, ex = window_nodes_side_by_side(
        ros_context, common, {"ahead": [], "after": [Parameter("window.describe_ahead", value=False)]})
    ahead, after = nodes["ahead"], nodes["after"]

    rng = np.random.default_rng(2)
    off_a = np.arange(50, dtype=np.int64) * 1_000_000
    off_f = np.arange(12, dtype=np.int64) * 4_000_000
    # 50 ms batches: 0.4 s released, 1.2 s touching (about 1.2 N), 0.5 s released, then again with the frame id
    # set on both nodes while the second exploration's release time runs
    touching = ([False] * 8 + [True] * 24 + [False] * 10) * 2
    renamed = False
    for k, touch in enumerate(touching):
        if k > 42 and not renamed and ahead.ahead.pending is not None:
            for node in (ahead, after):
                assert node.set_parameters([Parameter("frame_id", value="skin_renamed")])[0].successful
            renamed = True
        runs = []
        for cell in part.cells:
            acc = np.clip(rng.normal(0, 12, (3, 50)) + [[0], [0], [256]], -512, 511).astype(np.int16)
            force = rng.integers(300, 700, (3, 12)) if touch else rng.integers(0, 10, (3, 12))
            frame = SkinFrame(5_000_000_000 + k * 50_000_000, acc, off_a, force.astype(np.uint16), off_f,
                              np.zeros(0, np.uint16), sequence=k)
            runs.append(SkinRun(cell.id, frame, np.zeros(3)))
        pub.publish(skin_part_to_msg(pack_skin_part("left_hand", runs, force_n_per_count=0.0024)))
        # taken one by one, as a node keeping up with its input takes them
        assert spin_until(ex, lambda n=k + 1: ahead.frames_taken == after.frames_taken == n, 10)
    assert spin_until(ex, lambda: ahead.frames_taken == after.frames_taken == len(touching)
                      and len(out["desc_ahead"]) == len(out["desc_after"]) == 2, 20)
    # the first described during the release time and that descriptor published at the decision; the second's
    # description, made under the old frame id, not used
    assert renamed and after.ahead is None
    assert ahead.ahead.counts() == {"used": 1, "changed": 0, "discarded": 1} and len(ahead._ahead_ms) == 2
    for eid, (a, b) in enumerate(zip(out["desc_ahead"], out["desc_after"]), start=1):
        assert (a.window_start, a.window_end, a.exploration_id) == (b.window_start, b.window_end, b.exploration_id)
        assert a.exploration_id == eid and (b.window_end.sec * 10**9 + b.window_end.nanosec) \
            - (b.window_start.sec * 10**9 + b.window_start.nanosec) == pytest.approx(1.2e9, abs=0.02e9)
        assert list(a.values) == list(b.values) and all(math.isfinite(v) for v in a.values)
        assert a.header.frame_id == b.header.frame_id == ("skin_renamed" if eid == 2 else "base_link")
    status = ahead._status()
    assert status.values["described_ahead_used"] == 1 and status.values["describe_ahead_n"] == 2
    for n in (ahead, after, io):
        n.destroy_node()
