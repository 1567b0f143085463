"""One feature engine: the window node publishes, for a recorded window, what the evaluation computes.

A recording's frames go out as ``BioTacFrameBatch`` messages to a window node
(fixed windows cut exactly on frame stamps, moved onto the windows' grid); its ``Descriptor`` must equal
the evaluation's feature bank for the same frames, for the shipped groups and
the paper's.  And a model trained on one group selection refuses descriptors
of another, naming both.
"""

from __future__ import annotations

import numpy as np
import pytest
from node_helpers import spin_until

pytestmark = [pytest.mark.ros, pytest.mark.realdata]

N_FRAMES = 200  # a 2 s window
START = 37


def _messages(rec, ct, first: int, count: int, batch: int = 10, shift_ns: int = 0):
    from tactile_descriptors_ros.nodes.conversions import biotac_batch_to_msg
    from tactile_descriptors_ros.streams.frames import BioTacBatch

    ppf = rec.pac_per_frame
    out = []
    for s in range(first, first + count, batch):
        f = slice(s, s + batch)
        p = slice(s * ppf, (s + batch) * ppf)
        t0 = int(rec.frame_t_ns[s])
        b = BioTacBatch(stamp_ns=t0 + shift_ns, pac=rec.pac[p], pac_offset_ns=rec.pac_t_ns[p] - t0,
                        frame_offset_ns=rec.frame_t_ns[f] - t0, pdc=rec.pdc[f], tac=rec.tac[f], tdc=rec.tdc[f],
                        electrodes=rec.electrodes[:, f].T, first_frame_sequence=s)
        out.append(biotac_batch_to_msg(b, sensor_name="biotac_index", body_part="index", chip_select=1,
                                       force_n_per_count=ct.force.n_per_count, pdc_tare_counts=0.0))
    return out


@pytest.fixture(scope="module")
def recording(biotac_data_dir):
    from tactile_descriptors_lab.datasets.biotac_slide import load_recordings

    return load_recordings(biotac_data_dir, trials=[3], materials=[12])[0]


def _node_descriptor(ros_context, rec, groups, block_s=0.0):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor, DescriptorLayout
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.core.windowing import first_fixed_start
    from tactile_descriptors_ros.layouts import DescriptorLayouts
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    ct = load_robot("shadow_hand").cell_types["biotac"]
    length_ns = int(rec.frame_t_ns[START + N_FRAMES] - rec.frame_t_ns[START])
    w = WindowNode(context=ros_context, parameter_overrides=[
        Parameter("robot", value="shadow_hand"), Parameter("body_parts", value=["index"]),
        Parameter("window.mode", value="fixed"), Parameter("window.length_s", value=length_ns / 1e9),
        Parameter("window.hop_s", value=100.0), Parameter("window.lateness_s", value=0.0),
        Parameter("descriptor.groups", value=list(groups)), Parameter("descriptor.block_s", value=block_s),
        Parameter("qos.frames.reliability", value="reliable")])
    io = rclpy.create_node("io", context=ros_context)
    got, layouts = [], DescriptorLayouts()
    io.create_subscription(Descriptor, "tactile/descriptor", got.append, 10)
    io.create_subscription(DescriptorLayout, "tactile/descriptor_layout", layouts.add,
                           QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    pub = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 100)
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (w, io):
        ex.add_node(n)
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1, 10)
        # fixed windows lie on a grid of stamp time: moved onto it, the recording's window is the node's first
        first_ns = int(rec.pac_t_ns[START * rec.pac_per_frame])
        cut = w.windower
        shift_ns = first_fixed_start(first_ns, cut.length_ns, cut.hop_ns, cut.grid_margin_ns) - first_ns
        for m in _messages(rec, ct, START, N_FRAMES + 30, shift_ns=shift_ns):
            pub.publish(m)
            ex.spin_once(timeout_sec=0.002)
        assert spin_until(ex, lambda: len(got) >= 1 and layouts.of(got[0]) is not None, 20), \
            "no descriptor and layout from the window node"
        assert not any(w.faults.values()), dict(w.faults)
        assert list(got[0].labels) == []
        got[0].labels = list(layouts.of(got[0]))  # the layout's labels, for the comparisons below
        return got[0]
    finally:
        w.destroy_node()
        io.destroy_node()


@pytest.mark.parametrize("mode", ["combined", "paper"])
def test_window_node_publishes_the_evaluation_values(ros_context, recording, mode):
    from tactile_descriptors_lab.evaluation.bank import compute_bank, mode_groups, select_features
    from tactile_descriptors_lab.evaluation.sampling import Window
    from tactile_descriptors_ros.core.robot import load_robot

    groups = mode_groups(mode)
    msg = _node_descriptor(ros_context, recording, groups)
    bank = compute_bank([recording], [Window(recording.material, recording.trial, START, N_FRAMES)],
                        force_threshold_n=load_robot("shadow_hand").contact.force_threshold_n)
    assert bank.in_contact[0], "pick a window in contact: a gated window would compare zeros"
    want, labels = select_features(bank, mode, gate=True)
    assert list(msg.labels) == [f"index/{lab}" for lab in labels]
    assert msg.channel_mode == "+".join(groups)
    np.testing.assert_allclose(np.asarray(msg.values), want[0], rtol=1e-9, atol=1e-9)


def test_window_node_publishes_block_averaged_descriptors_of_the_core_function(ros_context, recording):
    from tactile_descriptors_lab.evaluation.bank import (
        finger_robot,
        mode_groups,
        recording_cells,
        select_features,
    )
    from tactile_descriptors_lab.evaluation.experiments import describe_windows
    from tactile_descriptors_lab.evaluation.sampling import Window
    from tactile_descriptors_ros.core.blocks import describe_blocks
    from tactile_descriptors_ros.core.robot import load_robot

    groups = mode_groups("combined")
    msg = _node_descriptor(ros_context, recording, groups, block_s=1.0)  # hop 0.5 s: 3 blocks of a 2 s window
    cells = recording_cells(recording.crop_frames(START, START + N_FRAMES))
    core = describe_blocks(finger_robot(), cells, block_s=1.0, block_hop_s=0.5, layout="concat", groups=groups)
    assert core.extra["blocks"] == 3
    single = describe_blocks(finger_robot(), cells, block_s=0.0, block_hop_s=0.5, layout="concat", groups=groups)
    assert np.max(np.abs(single.values - core.values) / (np.abs(core.values) + 1e-9)) > 1e-3  # blocks are on
    np.testing.assert_allclose(np.asarray(msg.values), core.values, rtol=1e-9, atol=1e-9)
    # and the evaluation's block-averaged bank of the same window
    bank = describe_windows([recording], [Window(recording.material, recording.trial, START, N_FRAMES)],
                            block_frames=100, hop_frames=50,
                            force_threshold_n=load_robot("shadow_hand").contact.force_threshold_n)
    want, _ = select_features(bank, "combined", gate=True)
    np.testing.assert_allclose(np.asarray(msg.values), want[0], rtol=1e-9, atol=1e-9)


def test_model_of_one_selection_refuses_another_naming_both():
    from tactile_descriptors_ros.core.groups import selection_labels
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.classifier_node import layout_mismatch
    from tactile_descriptors_ros.nodes.conversions import DescriptorSample

    ct = load_robot("shadow_hand").cell_types["biotac"]
    paper = tuple(f"index/{lab}" for lab in selection_labels(ct, ("paper",)))
    rich = tuple(f"index/{lab}" for lab in selection_labels(ct, ("per_channel", "bands", "levels", "statistics")))
    sample = DescriptorSample(1, 0, np.zeros(len(rich)), rich, True, "exploration", "shadow_hand", ("index",))
    text = layout_mismatch(sample, paper)
    assert "per_channel+bands+levels+statistics (261 values" in text and "trained on feature groups paper (8" in text


@pytest.mark.parametrize("groups, match", [
    (["per_channel", "levels:temperature"], r"'levels:temperature'.*'biotac'.*'temperature'"),
    (["paper", "wavelets"], "unknown feature group 'wavelets'"),
])
def test_window_node_refuses_groups_its_cell_type_cannot_feed_at_start_up(ros_context, groups, match):
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    with pytest.raises(ConfigError, match=match):
        WindowNode(context=ros_context, parameter_overrides=[
            Parameter("robot", value="shadow_hand"), Parameter("descriptor.groups", value=groups)])


@pytest.mark.parametrize("block_s, hop_s, key", [(-1.0, 0.5, "descriptor.block_s"),
                                                 (1.0, 2.0, "descriptor.block_hop_s"),
                                                 (0.02, 0.01, "descriptor.block_s")])
def test_window_node_refuses_a_bad_block_setting_naming_the_parameter(ros_context, block_s, hop_s, key):
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    with pytest.raises(ConfigError) as err:
        WindowNode(context=ros_context, parameter_overrides=[
            Parameter("robot", value="shadow_hand"), Parameter("descriptor.block_s", value=block_s),
            Parameter("descriptor.block_hop_s", value=hop_s)])
    assert key in str(err.value)


def test_extra_channel_no_message_carries_is_refused():
    import dataclasses

    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.nodes.conversions import message_kind

    ct = load_robot("shadow_hand").cell_types["biotac"]
    assert message_kind(ct) == "biotac"
    with pytest.raises(ConfigError, match="'humidity'.*BioTacFrameBatch"):
        message_kind(dataclasses.replace(ct, extra_channels=("pdc", "humidity")))
