"""Block averaging in the core: known answer on a real window, one block when short, bad settings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml

from tactile_descriptors_ros.core.aggregation import describe_window
from tactile_descriptors_ros.core.blocks import block_mean, block_starts, describe_blocks, split_cells
from tactile_descriptors_ros.core.robot import config_dir, load_robot, parse_robot
from tactile_descriptors_ros.errors import ConfigError


def test_block_starts_spread_evenly_and_cover_the_window():
    assert block_starts(200, 100, 50).tolist() == [0, 50, 100]
    starts = block_starts(599, 100, 50)
    assert len(starts) == 11 and starts[0] == 0 and starts[-1] == 499 and max(np.diff(starts)) <= 50
    assert block_starts(80, 100, 50).tolist() == [0]


def test_block_mean_averages_activity_in_log_and_the_rest_plainly():
    rows = np.array([[np.expm1(1.0), 2.0], [np.expm1(3.0), 4.0]])
    np.testing.assert_allclose(block_mean(rows, ("finger/paper/A_S", "finger/paper/M_S")), [np.expm1(2.0), 3.0])


@pytest.mark.parametrize("change, key", [
    ({"block_s": -1.0}, "descriptor.block_s"),
    ({"block_s": 1.0, "block_hop_s": 1.5}, "descriptor.block_hop_s"),
    ({"block_s": 1.0, "block_hop_s": 0}, "descriptor.block_hop_s"),
    ({"block_s": 0.02, "block_hop_s": 0.01}, "descriptor.block_s"),  # 2 frames at 100 Hz
    ({"block_s": "one"}, "descriptor.block_s"),
])
def test_bad_block_settings_are_config_errors_naming_the_key(change, key):
    data = yaml.safe_load((config_dir() / "shadow_hand.yaml").read_text())
    data["descriptor"].update(change)
    with pytest.raises(ConfigError) as err:
        parse_robot(data, source="hand.yaml")
    assert err.value.key == key


def test_shipped_shadow_hand_averages_1s_blocks_and_the_paper_mode_is_one_parameter_away():
    d = load_robot("shadow_hand").descriptor
    assert (d.block_s, d.block_hop_s) == (1.0, 0.5)
    data = yaml.safe_load((config_dir() / "shadow_hand.yaml").read_text())
    data["descriptor"]["block_s"] = 0
    assert parse_robot(data, source="hand.yaml").descriptor.block_s == 0.0


def _one_block_at_a_time(robot, cells, **kw):
    """Each block described on its own, then the blocks' values averaged per body part (what describe_blocks means)."""
    blocks = split_cells(cells, kw.pop("block_s"), kw.pop("block_hop_s"))
    descs = [describe_window(robot, b, **kw) for b in blocks]
    out = []
    for i in range(len(robot.body_parts)):
        parts = [d.body_parts[i] for d in descs]
        touching = [bp for bp in parts if bp.contact]
        out.append(block_mean(np.stack([bp.values for bp in touching]), parts[0].labels) if touching
                   else np.zeros(len(parts[0].labels)))
        assert descs[0].body_parts[i].labels == parts[-1].labels
    return out, len(blocks), [bp.quality for d in descs for bp in d.body_parts]


@pytest.mark.parametrize("robot_name, groups, layout", [
    ("shadow_hand", None, "concat"),
    ("shadow_hand", ("paper",), "pooled"),
    ("nao", ("paper", "bands", "levels", "statistics"), "concat"),
])
def test_all_blocks_in_one_call_equal_one_block_at_a_time(robot_name, groups, layout):
    """describe_blocks describes every block's cells in one call; each body part must come out bit for bit."""
    from tactile_descriptors_ros.sim.synthetic import biotac_window, skin_window

    robot = load_robot(robot_name)
    cells = biotac_window(robot, 2.0) if robot_name == "shadow_hand" else skin_window(robot, 2.0)
    some = sorted(cells)[1::3]  # some cells out of contact in every block
    for cid in some:
        cells[cid] = dataclasses.replace(cells[cid], force_n=np.zeros_like(np.asarray(cells[cid].force_n)))
    kw = {"block_s": 1.0, "block_hop_s": 0.5, "groups": groups, "layout": layout}
    got = describe_blocks(robot, cells, **kw)
    want, n_blocks, _ = _one_block_at_a_time(robot, cells, **{**kw, "layout": "concat"})
    assert got.extra["blocks"] == n_blocks >= 3
    for bp, values in zip(got.body_parts, want):
        np.testing.assert_array_equal(bp.values, values, err_msg=bp.name)
    if layout == "concat":
        assert got.labels == describe_window(robot, cells, groups=groups, layout="concat").labels
        np.testing.assert_array_equal(got.values, np.concatenate(want))
