"""The window node's per-message hot path: fast skin conversion (per cell and per body part) and frames taken in batches."""

from __future__ import annotations

import math

import numpy as np
import pytest
from node_helpers import left_hand_fixed_parameters, spin_until, window_nodes_side_by_side

pytestmark = pytest.mark.ros


def _reference_chunk(msg):
    """The straightforward conversion (via SkinFrame), the fast path's reference."""
    from tactile_descriptors_ros.markers import INVALID_ACCEL, INVALID_COUNT
    from tactile_descriptors_ros.nodes.conversions import skin_msg_to_frame

    f = skin_msg_to_frame(msg)
    forces = f.force.astype(np.int32)
    f_ok = np.all(f.force != INVALID_COUNT, axis=0)
    tare = np.asarray(msg.force_tare_counts, dtype=np.float64).reshape(3, 1)
    mean_n = (forces - tare).mean(axis=0) * float(msg.force_n_per_count)
    return {"vibration": f.accel.astype(np.int32), "vibration_t_ns": f.stamp_ns + f.accel_offset_ns,
            "deformation": forces, "deformation_t_ns": f.stamp_ns + f.force_offset_ns,
            "force_n": np.where(f_ok, mean_n, np.nan), "force_t_ns": f.stamp_ns + f.force_offset_ns,
            "vibration_valid": np.all(f.accel != INVALID_ACCEL, axis=0), "deformation_valid": f_ok}


def _skin_msg(rng, n_a, n_f, *, proximity=True, cdr=True):
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinCellFrame
    from tactile_descriptors_ros.nodes.conversions import skin_frame_to_msg
    from tactile_descriptors_ros.streams.frames import SkinFrame

    acc = rng.integers(-512, 512, (3, n_a)).astype(np.int16)
    force = rng.integers(0, 4096, (3, n_f)).astype(np.uint16)
    if n_a:
        acc[rng.integers(0, 3), rng.integers(0, n_a)] = -32768
    if n_f:
        force[rng.integers(0, 3), rng.integers(0, n_f)] = 65535
    frame = SkinFrame(int(rng.integers(0, 2**62)), acc, np.sort(rng.integers(0, 10**8, n_a)).astype(np.int64),
                      force, np.sort(rng.integers(0, 10**8, n_f)).astype(np.int64),
                      rng.integers(0, 100, n_f if proximity else 0).astype(np.uint16))
    msg = skin_frame_to_msg(frame, cell_id=3, body_part="left_hand", force_n_per_count=float(rng.uniform(0.001, 0.01)),
                            force_tare_counts=rng.uniform(0, 500, 3).tolist())
    # what the window node receives: rclpy's own array types after CDR
    return deserialize_message(serialize_message(msg), SkinCellFrame) if cdr else msg


@pytest.mark.parametrize("cdr", [True, False])
def test_fast_skin_conversion_equals_the_reference(cdr):
    from tactile_descriptors_ros.nodes.conversions import skin_msg_to_chunk

    rng = np.random.default_rng(4)
    for n_a, n_f in [(50, 12), (10, 3), (1, 1), (0, 0), (7, 0), (200, 50)]:
        msg = _skin_msg(rng, n_a, n_f, proximity=bool(n_f % 2), cdr=cdr)
        got, want = skin_msg_to_chunk(msg), _reference_chunk(msg)
        for key, value in want.items():
            arr = getattr(got, key)
            assert arr.dtype == value.dtype and arr.shape == value.shape, key
            np.testing.assert_array_equal(arr, value, err_msg=key)  # exact, NaN where invalid
        if n_f:
            assert np.isnan(got.force_n).sum() == (~got.deformation_valid).sum() >= 1


@pytest.mark.parametrize("field,value,match", [
    ("accel_y", [1, 2], "axes differ"),
    ("accel_offset_ns", [0], "accel must be"),
    ("force", [1, 2, 3, 4], "multiple of 3"),
    ("force_offset_ns", [0, 1, 2], "force must be"),
    ("proximity", [1, 2, 3, 4, 5], "proximity"),
])
def test_fast_skin_conversion_rejects_inconsistent_lengths(field, value, match):
    import array

    from tactile_descriptors_ros.errors import SignalError
    from tactile_descriptors_ros.nodes.conversions import skin_msg_to_chunk

    msg = _skin_msg(np.random.default_rng(1), 5, 2)
    code = {"accel_y": "h", "accel_offset_ns": "q", "force": "H", "force_offset_ns": "q", "proximity": "H"}[field]
    setattr(msg, field, array.array(code, value))
    with pytest.raises(SignalError, match=match):
        skin_msg_to_chunk(msg)


def _runs(rng, cells, *, n_a=None, n_f=None):
    """Random cell batches with invalid markers, some without proximity, own stamps and tares."""
    from tactile_descriptors_ros.streams.frames import SkinFrame
    from tactile_descriptors_ros.streams.skin_parts import SkinRun

    runs = []
    for k, cid in enumerate(cells):
        a = int(rng.integers(1, 60)) if n_a is None else n_a
        f = int(rng.integers(0, 15)) if n_f is None else n_f
        acc = rng.integers(-512, 512, (3, a)).astype(np.int16)
        force = rng.integers(0, 4096, (3, f)).astype(np.uint16)
        acc[rng.integers(0, 3), rng.integers(0, a)] = -32768
        if f:
            force[rng.integers(0, 3), rng.integers(0, f)] = 65535
        prox = rng.integers(0, 100, f if k % 2 else 0).astype(np.uint16)
        off_a = np.sort(rng.choice(10**8, a, replace=False)).astype(np.int64)
        frame = SkinFrame(10**12 + int(rng.integers(0, 10**7)), acc, off_a - off_a[0],  # stamp: first accel sample
                          force, np.sort(rng.choice(10**8, f, replace=False)).astype(np.int64), prox,
                          temperature_c=float(rng.uniform(20, 35)) if k != 1 else math.nan,
                          sequence=int(rng.integers(0, 2**32)), bad_frames=int(rng.integers(0, 3)))
        runs.append(SkinRun(cid, frame, rng.uniform(0, 500, 3)))
    return runs


@pytest.mark.parametrize("cdr", [True, False])
def test_part_message_chunks_equal_the_per_cell_messages(cdr):
    """One SkinPartFrames gives, per cell, exactly the chunk its own SkinCellFrame gave (NaN where invalid)."""
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.nodes.conversions import (
        skin_frame_to_msg,
        skin_msg_to_chunk,
        skin_part_msg_to_chunks,
        skin_part_to_msg,
    )
    from tactile_descriptors_ros.streams.skin_parts import pack_skin_part

    rng = np.random.default_rng(7)
    for cells in ([3], [3, 4, 5, 6], [9, 9, 2]):  # a cell may have two consecutive runs
        runs = _runs(rng, cells)
        msg = skin_part_to_msg(pack_skin_part("left_hand", runs, force_n_per_count=0.0024))
        if cdr:
            msg = deserialize_message(serialize_message(msg), SkinPartFrames)
        extra = ("proximity", "temperature")
        got = skin_part_msg_to_chunks(msg, extra)
        assert [cid for cid, _ in got] == cells
        for (cid, chunk), run in zip(got, runs):
            want = skin_msg_to_chunk(skin_frame_to_msg(run.frame, cell_id=cid, body_part="left_hand",
                                                       force_n_per_count=0.0024, force_tare_counts=run.tare_counts),
                                     extra)
            for key in ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "force_t_ns",
                        "vibration_valid", "deformation_valid", "extra", "deformation_tare"):
                a, b = getattr(chunk, key), getattr(want, key)
                assert a.dtype == b.dtype and a.shape == b.shape, key
                np.testing.assert_array_equal(a, b, err_msg=key)


@pytest.mark.parametrize("cdr", [True, False])
def test_compiled_part_conversion_equals_the_numpy_path_to_the_bit(cdr):
    """The window node's conversion of a body part's message by the compiled intake gives the arrays of the
    numpy path, dtype, shape and bits; tares far from the counts make the force's order of sums show."""
    from unittest import mock

    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.core import fast, windowing
    from tactile_descriptors_ros.nodes.conversions import (
        _part_chunk_compiled,
        skin_part_msg_to_part_chunk,
        skin_part_to_msg,
    )
    from tactile_descriptors_ros.streams.skin_parts import pack_skin_part

    if fast.kernel_module() is None:
        pytest.skip("no compiled backend")
    rng = np.random.default_rng(11)
    for cells in ([3], [3, 4, 5, 6], [9, 9, 2], list(range(20, 37))):
        for extra in ((), ("proximity", "temperature"), ("temperature",), ("temperature", "proximity")):
            runs = _runs(rng, cells)
            for run in runs[::2]:
                run.tare_counts[:] = rng.uniform(-1e5, 1e5, 3)
            msg = skin_part_to_msg(pack_skin_part("left_hand", runs, force_n_per_count=rng.uniform(1e-4, 1e-2)))
            if cdr:
                msg = deserialize_message(serialize_message(msg), SkinPartFrames)
            assert _part_chunk_compiled(msg, extra) is not None  # the compiled path serves this message
            got = skin_part_msg_to_part_chunk(msg, extra)
            with mock.patch.object(windowing, "COMPILED_INTAKE", False):
                assert _part_chunk_compiled(msg, extra) is None
                want = skin_part_msg_to_part_chunk(msg, extra)
            for key in ("cell_ids", "vibration_count", "deformation_count", "vibration", "vibration_t_ns",
                        "deformation", "deformation_t_ns", "force_n", "vibration_valid", "deformation_valid",
                        "extra", "deformation_tare"):
                a, b = getattr(got, key), getattr(want, key)
                if b is None:
                    assert a is None, key
                    continue
                assert a.dtype == b.dtype and a.shape == b.shape, key
                assert a.tobytes() == np.ascontiguousarray(b).tobytes(), key  # NaN where NaN, every bit


def test_part_message_round_trip_gives_back_every_cell_batch():
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.nodes.conversions import skin_part_from_msg, skin_part_to_msg
    from tactile_descriptors_ros.streams.skin_parts import pack_skin_part

    runs = _runs(np.random.default_rng(3), [11, 12, 13])
    msg = deserialize_message(serialize_message(skin_part_to_msg(pack_skin_part("chest", runs))), SkinPartFrames)
    assert msg.body_part == "chest" and msg.header.frame_id == "chest" and list(msg.cell_ids) == [11, 12, 13]
    back = skin_part_from_msg(msg).frames()
    for (cid, frame, tare), run in zip(back, runs):
        assert cid == run.cell_id
        np.testing.assert_array_equal(tare, run.tare_counts)
        for key in ("stamp_ns", "sequence", "bad_frames"):
            assert getattr(frame, key) == getattr(run.frame, key), key
        assert (math.isnan(frame.temperature_c) and math.isnan(run.frame.temperature_c)) \
            or frame.temperature_c == run.frame.temperature_c
        for key in ("accel", "accel_offset_ns", "force", "force_offset_ns", "proximity"):
            np.testing.assert_array_equal(getattr(frame, key), getattr(run.frame, key), err_msg=key)


@pytest.mark.parametrize("field,value,match", [
    ("accel_y", [1, 2], "axes differ"),
    ("accel_offset_ns", [0], "accelerometer offsets"),
    ("force", [1, 2, 3, 4], "multiple of 3"),
    ("force_offset_ns", [0, 1, 2], "force offsets"),
    ("proximity", [1, 2, 3, 4, 5], "proximity"),
    ("accel_count", [1, 2], "accel"),
    ("force_count", [5, 9], "force must be"),
    ("force_tare_counts", [1.0, 2.0], "3 values per cell run"),
    ("sequence", [1], "sequence values"),
])
def test_part_message_with_inconsistent_lengths_is_rejected(field, value, match):
    import array

    from tactile_descriptors_ros.errors import SignalError
    from tactile_descriptors_ros.nodes.conversions import (
        skin_part_msg_to_chunks,
        skin_part_msg_to_part_chunk,
        skin_part_to_msg,
    )
    from tactile_descriptors_ros.streams.skin_parts import pack_skin_part

    msg = skin_part_to_msg(pack_skin_part("left_hand", _runs(np.random.default_rng(1), [1, 2], n_a=5, n_f=2)))
    skin_part_msg_to_chunks(msg)  # consistent as built
    code = {"accel_y": "h", "accel_offset_ns": "q", "force": "H", "force_offset_ns": "q", "proximity": "H",
            "accel_count": "I", "force_count": "I", "force_tare_counts": "d", "sequence": "I"}[field]
    setattr(msg, field, array.array(code, value))
    with pytest.raises(SignalError, match=match):
        skin_part_msg_to_chunks(msg)
    with pytest.raises(SignalError, match=match):  # the window node's path (compiled where it is loaded) too
        skin_part_msg_to_part_chunk(msg)


def _publish_left_hand(pub, t0: int, rounds: int = 24) -> int:
    """``rounds`` 50 ms batches of every left-hand cell from ``t0``, each in two messages; how many."""
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg
    from tactile_descriptors_ros.streams.frames import SkinFrame
    from tactile_descriptors_ros.streams.skin_parts import SkinRun, pack_skin_part

    part = load_robot("nao").body_part("left_hand")
    rng = np.random.default_rng(0)
    off_a = np.arange(50, dtype=np.int64) * 1_000_000
    off_f = np.arange(12, dtype=np.int64) * 4_000_000
    half = len(part.cells) // 2
    for k in range(rounds):
        runs = []
        for cell in part.cells:
            acc = np.clip(rng.normal(0, 12, (3, 50)) + [[0], [0], [256]], -512, 511).astype(np.int16)
            force = rng.integers(300, 700, (3, 12)).astype(np.uint16)
            frame = SkinFrame(t0 + k * 50_000_000, acc, off_a, force, off_f, np.zeros(0, np.uint16), sequence=k)
            runs.append(SkinRun(cell.id, frame, np.zeros(3)))
        for piece in (runs[:half], runs[half:]):  # a body part's cells in two messages per batch
            pub.publish(skin_part_to_msg(pack_skin_part("left_hand", piece, force_n_per_count=0.0024)))
    return 2 * rounds


def _assert_same_descriptors(a_list, b_list, n_cells: int) -> None:
    for a, b in zip(a_list, b_list, strict=True):
        assert (a.window_start, a.window_end) == (b.window_start, b.window_end)
        assert list(a.values) == list(b.values) and all(math.isfinite(v) for v in a.values)
        assert list(a.cells_total) == [n_cells]


def test_window_node_takes_waiting_frames_in_one_callback_with_the_same_descriptors(ros_context):
    """A node behind its input takes every waiting frame in one callback; the windows are those of one-by-one."""
    from rclpy.parameter import Parameter

    common = left_hand_fixed_parameters()
    nodes, io, pub, out, ex = window_nodes_side_by_side(
        ros_context, common, {"batched": [], "single": [Parameter("frames.drain_max", value=0)]})
    batched, single = nodes["batched"], nodes["single"]

    # 1.2 s of 50 ms batches from the start of a window on the windows' grid: windows end at 0.5, 0.75, 1.0 s
    n_msgs = _publish_left_hand(pub, 5_000_000_000 - batched.windower.grid_margin_ns)
    assert spin_until(ex, lambda: batched.frames_taken == n_msgs and single.frames_taken == n_msgs
                      and len(out["desc_batched"]) == len(out["desc_single"]) == 3, 20)
    assert batched.largest_batch > 1 and batched.batches < n_msgs  # it caught up in batches
    assert single.largest_batch == 1 and single.batches == n_msgs
    assert batched.faults == single.faults and batched.windower.faults == single.windower.faults
    assert not +batched.faults  # every run in sequence, every cell known (no count above zero)
    # each rehearsed its describing path at its first frames (kernel ready), and published nothing for it
    assert batched.rehearsal_ms is not None and single.rehearsal_ms is not None
    assert batched.descriptors_published == single.descriptors_published == 3
    _assert_same_descriptors(out["desc_batched"], out["desc_single"], len(batched.robot.body_part("left_hand").cells))
    for n in (batched, single, io):
        n.destroy_node()


def test_frames_read_from_their_bytes_give_the_descriptors_rclpys_messages_give(ros_context):
    """A node that takes the frames serialised (the default) and one that lets rclpy build them
    (``frames.serialized`` false) publish the same descriptors; bytes that are no SkinPartFrames are counted
    as malformed by the first, which goes on."""
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.codecs import cdr

    if not cdr.available():
        pytest.skip("no compiled backend: both nodes let rclpy build the messages")
    nodes, io, pub, out, ex = window_nodes_side_by_side(
        ros_context, left_hand_fixed_parameters(),
        {"bytes": [], "rclpy": [Parameter("frames.serialized", value=False)]})
    by_bytes, by_rclpy = nodes["bytes"], nodes["rclpy"]
    assert by_bytes.frames_serialized and not by_rclpy.frames_serialized
    assert by_bytes.subs[0].raw and not by_rclpy.subs[0].raw
    n_msgs = _publish_left_hand(pub, 5_000_000_000 - by_bytes.windower.grid_margin_ns)
    assert spin_until(ex, lambda: by_bytes.frames_taken == by_rclpy.frames_taken == n_msgs
                      and len(out["desc_bytes"]) == len(out["desc_rclpy"]) == 3, 20)
    assert not +by_bytes.faults and not +by_rclpy.faults
    assert by_bytes.windower.faults == by_rclpy.windower.faults
    _assert_same_descriptors(out["desc_bytes"], out["desc_rclpy"], len(by_bytes.robot.body_part("left_hand").cells))
    by_rclpy.destroy_node()  # rclpy's take would raise on the bytes below
    assert spin_until(ex, lambda: pub.get_subscription_count() == 1, 10)
    pub.publish(b"\x00\x01\x00\x00" + b"\xff" * 8)  # a length past the end: rclpy cannot read it either
    assert spin_until(ex, lambda: by_bytes.faults["malformed"] == 1, 10)
    assert by_bytes.frames_taken == n_msgs + 1
    for n in (by_bytes, io):
        n.destroy_node()


def test_nao_graph_window_parameters_are_the_nodes_own(ros_context):
    """The latency defaults in config/nao.yaml's nodes: section reach the window node under their declared names."""
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    for split in (False, True):
        spec = next(s for s in build_graph("nao", split_window_nodes=split) if s.executable == "window_node")
        params = spec.parameters
        assert params["window.lateness_s"] == 0.0 and params["frames.drain_max"] == 1000
        assert params["qos.frames.depth"] == 256
    node = WindowNode(spec.name, context=ros_context,
                      parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    try:
        for key, value in params.items():
            assert node.has_parameter(key), key
            assert node.get_parameter(key).value == value, key
        assert node.params["frames.drain_max"] == 1000 and node.windower.lateness_ns == 0
        assert [p.name for p in node.robot.body_parts] == params["body_parts"]
    finally:
        node.destroy_node()


def test_the_newest_sample_of_a_message_is_found_whichever_way_it_was_read():
    """A frames message's newest vibration sample (the frames' age on arrival): rclpy's message (``array``
    fields), the same read from its bytes (numpy views), a BioTac batch; none for a message without samples."""
    from rclpy.serialization import serialize_message

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, SkinPartFrames
    from tactile_descriptors_ros.codecs.cdr import available, read_skin_part
    from tactile_descriptors_ros.nodes.window_node import _newest_sample_ns

    msg = SkinPartFrames()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 250
    assert _newest_sample_ns(msg) is None
    msg.accel_offset_ns = [30, 9_000_000, -5, 8_999_999]
    want = 1_700_000_000 * 10**9 + 250 + 9_000_000
    assert _newest_sample_ns(msg) == want
    if available():  # read from its bytes (the compiled backend)
        view = read_skin_part(serialize_message(msg))
        assert isinstance(view.accel_offset_ns, np.ndarray)
        assert _newest_sample_ns(view) == want
    bt = BioTacFrameBatch()
    bt.header.stamp.sec = 3
    bt.pac_offset_ns = [7, 41, 2]
    assert _newest_sample_ns(bt) == 3 * 10**9 + 41
