"""Message <-> core conversions: round trips, invalid samples, units."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def _batch(n_frames=3, n_el=19, t0=5_000_000_123):
    from tactile_descriptors_ros.streams.frames import BioTacBatch

    rng = np.random.default_rng(1)
    pac = rng.integers(0, 4096, n_frames * 22).astype(np.uint16)
    pac[5] = 65535
    el = rng.integers(0, 4096, (n_frames, n_el)).astype(np.uint16)
    el[1, 4] = 65535
    pdc = np.array([2100, 65535, 2300][:n_frames], np.uint16)
    return BioTacBatch(t0, pac, np.arange(n_frames * 22, dtype=np.int64) * 454_545,
                       np.arange(n_frames, dtype=np.int64) * 10_000_000, pdc, pdc, pdc, el, 7, 2)


def test_biotac_round_trip_and_chunk():
    from tactile_descriptors_ros.nodes.conversions import biotac_batch_to_msg, biotac_msg_to_batch, biotac_msg_to_chunk

    b = _batch()
    msg = biotac_batch_to_msg(b, sensor_name="biotac_index", body_part="index", chip_select=1,
                              force_n_per_count=0.05, pdc_tare_counts=2000.0, electrode_tare_counts=[1.0] * 19)
    back = biotac_msg_to_batch(msg)
    for name in ("pac", "pac_offset_ns", "frame_offset_ns", "pdc", "tac", "tdc", "electrodes"):
        np.testing.assert_array_equal(getattr(back, name), getattr(b, name))
    assert (back.stamp_ns, back.first_frame_sequence, back.bad_words) == (b.stamp_ns, 7, 2)
    ch = biotac_msg_to_chunk(msg)
    assert ch.vibration.shape == (1, 66) and ch.deformation.shape == (19, 3)
    assert not ch.vibration_valid[5] and ch.vibration_valid.sum() == 65
    np.testing.assert_array_equal(ch.deformation_valid, [True, False, True])
    assert ch.force_n[0] == pytest.approx(5.0) and math.isnan(ch.force_n[1]) and ch.force_n[2] == pytest.approx(15.0)
    assert ch.vibration_t_ns[0] == b.stamp_ns and ch.deformation_t_ns[2] == b.stamp_ns + 20_000_000


def test_inconsistent_lengths_are_errors():
    from tactile_descriptors_ros.errors import SignalError
    from tactile_descriptors_ros.nodes.conversions import biotac_batch_to_msg, biotac_msg_to_chunk
    from tactile_descriptors_ros.streams.frames import BioTacBatch

    with pytest.raises(SignalError):
        BioTacBatch(0, np.zeros(3, np.uint16), np.zeros(2, np.int64), np.zeros(1, np.int64),
                    np.zeros(1, np.uint16), np.zeros(1, np.uint16), np.zeros(1, np.uint16), np.zeros((1, 19), np.uint16))
    msg = biotac_batch_to_msg(_batch(), sensor_name="s", body_part="index", chip_select=0)
    msg.frame_count = 4
    with pytest.raises(SignalError):
        biotac_msg_to_chunk(msg)


def test_skin_round_trip_and_chunk():
    from tactile_descriptors_ros.nodes.conversions import (
        skin_frame_to_msg,
        skin_msg_to_chunk,
        skin_msg_to_frame,
    )
    from tactile_descriptors_ros.streams.frames import SkinFrame

    acc = np.array([[1, 2, -3, 4], [0, -512, 7, 8], [9, 10, 11, -32768]], np.int16)
    force = np.array([[100, 200], [110, 65535], [120, 220]], np.uint16)
    f = SkinFrame(1_000, acc, np.arange(4, dtype=np.int64) * 1_000_000, force,
                  np.array([0, 4_000_000], np.int64), np.array([5, 6], np.uint16), 31.5, 9, 1)
    msg = skin_frame_to_msg(f, cell_id=17, body_part="right_hand", force_n_per_count=0.01,
                            force_tare_counts=[100, 110, 120])
    back = skin_msg_to_frame(msg)
    np.testing.assert_array_equal(back.accel, acc)
    np.testing.assert_array_equal(back.force, force)
    assert back.temperature_c == 31.5 and back.sequence == 9
    ch = skin_msg_to_chunk(msg)
    np.testing.assert_array_equal(ch.vibration_valid, [True, True, True, False])
    np.testing.assert_array_equal(ch.deformation_valid, [True, False])
    assert ch.force_n[0] == pytest.approx(0.0) and math.isnan(ch.force_n[1])


def test_descriptor_and_prediction_messages():
    from tactile_descriptors_ros.core.aggregation import describe_window
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.core.windowing import Window
    from tactile_descriptors_ros.errors import SignalError
    from tactile_descriptors_ros.nodes.conversions import (
        descriptor_from_msg,
        descriptor_layout_to_msg,
        descriptor_to_msg,
        layout_id,
        prediction_to_msg,
    )

    robot = load_robot("shadow_hand")
    d = describe_window(robot, {})
    msg = descriptor_to_msg(d, Window(1_000, 2_000_000_001, 4, "exploration"), frame_id="hand")
    layout = descriptor_layout_to_msg(d, frame_id="hand")
    assert list(msg.labels) == [] and msg.layout_id == layout.layout_id == layout_id(d.labels)
    assert tuple(layout.labels) == d.labels and layout.header.frame_id == "hand"
    with pytest.raises(SignalError, match="1305 values but its layout"):
        descriptor_from_msg(msg)  # the values without their layout's labels
    s = descriptor_from_msg(msg, layout.labels)
    assert s.exploration_id == 4 and s.window_end_ns == 2_000_000_001 and len(s.values) == 5 * 261  # shipped groups
    assert s.labels == d.labels and not s.contact and s.body_parts[0] == "thumb"
    p = prediction_to_msg(s, class_name=None, class_names=[], scores=np.zeros(0), model_version=0, updates=0)
    assert not p.has_model and p.class_name == "" and p.exploration_id == 4
    assert p.header.frame_id == "hand"  # the descriptor's frame, unless the classifier sets its own
    assert prediction_to_msg(s, class_name=None, class_names=[], scores=np.zeros(0), model_version=0, updates=0,
                             frame_id="base").header.frame_id == "base"


def test_stamp_conversion():
    from tactile_descriptors_ros.errors import SignalError
    from tactile_descriptors_ros.nodes.conversions import ns_to_stamp, stamp_to_ns

    assert stamp_to_ns(ns_to_stamp(12_345_678_901)) == 12_345_678_901
    with pytest.raises(SignalError):
        ns_to_stamp(-1)


def test_extra_channels_and_tares_reach_the_chunk():
    from tactile_descriptors_ros.markers import INVALID_COUNT
    from tactile_descriptors_ros.nodes.conversions import (
        biotac_batch_to_msg,
        biotac_msg_to_chunk,
        skin_frame_to_msg,
        skin_msg_to_chunk,
    )
    from tactile_descriptors_ros.streams.frames import BioTacBatch, SkinFrame

    b = BioTacBatch(stamp_ns=10, pac=np.array([1, 2], np.uint16), pac_offset_ns=np.array([0, 5]),
                    frame_offset_ns=np.array([0, 5]), pdc=np.array([300, INVALID_COUNT], np.uint16),
                    tac=np.array([7, 8], np.uint16), tdc=np.array([2000, 2001], np.uint16),
                    electrodes=np.full((2, 19), 1000, np.uint16))
    msg = biotac_batch_to_msg(b, sensor_name="s", body_part="index", chip_select=1, pdc_tare_counts=100.0,
                              electrode_tare_counts=np.arange(19.0))
    ch = biotac_msg_to_chunk(msg, ("pdc", "tdc", "tac"))
    np.testing.assert_array_equal(ch.extra[:, 0], [200.0, 2000.0, 7.0])  # PDC tared like the force
    assert math.isnan(ch.extra[0, 1]) and ch.extra[2, 1] == 8.0
    np.testing.assert_array_equal(ch.deformation_tare, np.arange(19.0))
    assert biotac_msg_to_chunk(msg).extra is None
    f = SkinFrame(stamp_ns=0, accel=np.zeros((3, 4), np.int16), accel_offset_ns=np.arange(4),
                  force=np.full((3, 2), 500, np.uint16), force_offset_ns=np.arange(2),
                  proximity=np.array([900, INVALID_COUNT], np.uint16), temperature_c=30.25)
    sk = skin_msg_to_chunk(skin_frame_to_msg(f, cell_id=1, body_part="left_hand", force_tare_counts=(1, 2, 3)),
                           ("proximity", "temperature"))
    assert sk.extra[0, 0] == 900.0 and math.isnan(sk.extra[0, 1]) and list(sk.extra[1]) == [30.25, 30.25]
    np.testing.assert_array_equal(sk.deformation_tare, [1.0, 2.0, 3.0])
    f.proximity = np.zeros(0, np.uint16)
    f.temperature_c = float("nan")
    none = skin_msg_to_chunk(skin_frame_to_msg(f, cell_id=1, body_part="left_hand"), ("proximity", "temperature"))
    assert np.isnan(none.extra).all()  # missing stays missing: the levels group flags it, never zeros
