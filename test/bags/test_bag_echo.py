"""``tactile echo`` statistics on known messages, from a bag (no live traffic needed)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from conftest import make_batch, make_descriptor, make_label, make_prediction
from tactile_descriptors_ros.bags.echo import echo_bag, type_constants
from tactile_descriptors_ros.bags.io import BagWriter
from tactile_descriptors_ros.bags.summary import EchoTracker, format_summary, message_to_dict, quality_names, to_yaml
from tactile_descriptors_ros.tools.cli import main

T0 = 1_700_000_000_000_000_000
BATCH = "tactile_descriptors_msgs/msg/BioTacFrameBatch"


def test_biotac_statistics_invalid_samples_and_gaps(store):
    tracker = EchoTracker(type_constants(store))
    pac = np.arange(44) * 10
    first = make_batch(store, T0, 0, pac=pac, pdc=[4, 8], invalid_at=(3, 40))
    s = tracker.summarize("/f", BATCH, first, T0)
    valid = np.delete(pac, [3, 40])
    st = s["channels"]["pac"]
    assert st["n"] == 44 and st["invalid"] == 2
    assert (st["min"], st["max"]) == (0, 430) and st["mean"] == pytest.approx(valid.mean())
    assert s["invalid_samples"] == 2
    assert s["force_n"]["mean"] == pytest.approx(0.3) and s["force_n"]["max"] == pytest.approx(0.4)
    assert s["channels"]["e1"] == {"n": 2, "invalid": 0, "min": 0, "max": 19, "mean": 9.5}
    assert s["frame_rate_hz"] == pytest.approx(100.0)
    assert s["lost_frames"] == 0 and s["stamp_gap_ns"] is None
    # the next batch continues exactly: no gap
    s2 = tracker.summarize("/f", BATCH, make_batch(store, T0 + 20_000_000, 2), T0 + 100_000_000)
    assert s2["lost_frames"] == 0 and s2["stamp_gap_ns"] is None
    assert s2["stream"]["rate_hz"] == pytest.approx(10.0)
    # 3 frames lost: sequence jumps from 4 to 7 and the stamp by 30 ms
    s3 = tracker.summarize("/f", BATCH, make_batch(store, T0 + 70_000_000, 7), T0 + 200_000_000)
    assert s3["lost_frames"] == 3 and s3["stamp_gap_ns"] == 30_000_000
    assert s3["stream"]["lost"] == 3 and s3["stream"]["sequence_gaps"] == 1 and s3["stream"]["stamp_gaps"] == 1
    text = format_summary(s3)
    assert "LOST 3 frames" in text and "stamp gap +30.000 ms" in text


def test_biotac_inconsistent_lengths_are_reported(store):
    bad = make_batch(store, T0, 0)
    bad.pdc = np.array([1], dtype=np.uint16)
    s = EchoTracker().summarize("/f", BATCH, bad, T0)
    assert any("pdc has 1 samples" in p for p in s["problems"])


def test_descriptor_quality_flags_and_values(store):
    msgtype = "tactile_descriptors_msgs/msg/Descriptor"
    s = EchoTracker(type_constants(store)).summarize("/d", msgtype, make_descriptor(store, T0), T0)
    thumb, index = s["body_parts"]["thumb"], s["body_parts"]["index"]
    assert thumb["contact"] is False and thumb["quality_flags"] == ["SHORT", "NO_CONTACT"]
    assert index["quality_flags"] == ["INVALID", "BIT10"]  # an unknown bit is shown, not dropped
    assert index["values"] == {"A_pac": 1500.0, "M_pac": 310.5} and index["mean_force_n"] == 1.25
    assert s["window_s"] == pytest.approx(2.0)
    assert "quality SHORT,NO_CONTACT" in format_summary(s)
    consts = store.fielddefs[msgtype][0]
    assert quality_names(0, consts) == []


def test_prediction_top_scores(store):
    s = EchoTracker(type_constants(store), top_k=2).summarize(
        "/p", "tactile_descriptors_msgs/msg/Prediction", make_prediction(store, T0), T0)
    assert [t["class_name"] for t in s["top"]] == ["felt", "cotton"]
    assert s["margin"] == pytest.approx(0.5) and s["classes"] == 4


def test_raw_yaml_is_the_full_message(store):
    msg = make_label(store, T0, "steel")
    assert yaml.safe_load(to_yaml(msg)) == message_to_dict(msg)
    assert message_to_dict(msg)["class_name"] == "steel"


def test_echo_command_reads_a_bag(tmp_path, store, capsys):
    path = tmp_path / "bag"
    with BagWriter(path) as bag:
        bag.add_topic("/frames", BATCH)
        bag.add_topic("/label", "tactile_descriptors_msgs/msg/Label")
        for k in range(4):
            seq = 2 * k + (3 if k == 3 else 0)  # last batch after 3 lost frames
            bag.write("/frames", T0 + k * 100_000_000, make_batch(store, T0 + seq * 10_000_000, seq))
        bag.write("/label", T0 + 500_000_000, make_label(store, T0 + 500_000_000))
    assert [m.topic for m, _ in echo_bag(str(path), "/frames", count=2)] == ["/frames"] * 2
    assert main(["echo", "/frames", "--bag", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["count"] == 4 and out["type"] == BATCH
    assert out["streams"]["/frames#biotac_index"]["lost"] == 3
    assert main(["echo", "/label", "--bag", str(path)]) == 0
    assert "label 'cork' for exploration 3" in capsys.readouterr().out
    assert main(["echo", "/frames", "--bag", str(path), "--raw", "--count", "1"]) == 0
    raw = yaml.safe_load(capsys.readouterr().out.split("---")[0])
    assert raw["first_frame_sequence"] == 0 and len(raw["pac"]) == 44
    assert main(["echo", "/nope", "--bag", str(path)]) == 2  # unknown topic: a clear error, exit 2


def _skin_part(store, stamp_ns: int, seq: int, cells=(4, 5), invalid_accel_at=()):
    """A rosbags SkinPartFrames: per cell 10 accelerometer samples (1 kHz) and 3 force samples (250 Hz)."""
    from conftest import _header

    cls = store.types["tactile_descriptors_msgs/msg/SkinPartFrames"]
    n = len(cells)
    ax = np.tile(np.arange(10, dtype=np.int16), n)
    for i in invalid_accel_at:
        ax[i] = cls.INVALID_ACCEL
    force = np.tile(np.array([[110, 120, 130]], dtype=np.uint16), (3 * n, 1)).reshape(-1)
    return cls(
        header=_header(store, stamp_ns, "chest"), body_part="chest",
        cell_ids=np.array(cells, np.uint32), sequence=np.full(n, seq, np.uint32),
        accel_count=np.full(n, 10, np.uint32), force_count=np.full(n, 3, np.uint32),
        temperature_c=np.array([30.0 + k for k in range(n)]), force_tare_counts=np.tile([10.0, 20.0, 30.0], n),
        bad_frames=np.zeros(n, np.uint32), accel_x=ax, accel_y=np.zeros(10 * n, np.int16),
        accel_z=np.zeros(10 * n, np.int16), accel_offset_ns=np.tile(np.arange(10, dtype=np.int64) * 1_000_000, n),
        accel_mps2_per_count=0.038, force=force, force_offset_ns=np.tile(np.arange(3, dtype=np.int64) * 4_000_000, n),
        force_n_per_count=0.01, proximity=np.zeros(0, np.uint16), proximity_per_count=0.0)


def test_skin_part_statistics_per_cell_health_and_lengths(store):
    msgtype = "tactile_descriptors_msgs/msg/SkinPartFrames"
    tracker = EchoTracker(type_constants(store))
    s = tracker.summarize("/tactile/chest/frames", msgtype, _skin_part(store, T0, 0, invalid_accel_at=(2,)), T0)
    assert (s["body_part"], s["cells"], s["runs"], s["accel_samples"], s["force_samples"]) == ("chest", 2, 2, 20, 6)
    assert s["accel_rate_hz"] == pytest.approx(1000.0)
    assert s["channels"]["accel_x"]["invalid"] == 1 and s["invalid_samples"] == 1
    assert s["force_n"]["mean"] == pytest.approx(1.0)  # (120 - 20) counts x 0.01 N, each cell with its tare
    assert s["temperature_c"]["min"] == 30.0 and s["temperature_c"]["max"] == 31.0
    assert s["lost_messages"] == 0 and not s["stamp_gaps_ns"] and not s["problems"]
    # the next batch: both cells continue exactly
    s2 = tracker.summarize("/tactile/chest/frames", msgtype, _skin_part(store, T0 + 10_000_000, 1), T0 + 10_000_000)
    assert s2["lost_messages"] == 0 and not s2["stamp_gaps_ns"]
    # two batches of both cells lost: 4 cell batches, and a 20 ms stamp gap for each cell
    s3 = tracker.summarize("/tactile/chest/frames", msgtype, _skin_part(store, T0 + 40_000_000, 4), T0 + 40_000_000)
    assert s3["lost_messages"] == 4 and s3["stamp_gaps_ns"] == [20_000_000, 20_000_000]
    assert s3["stream"]["lost"] == 4 and s3["stream"]["messages"] == 3
    text = format_summary(s3)
    assert "chest: 2 cells in 2 runs" in text and "LOST 4 cell batches" in text and "+20.000" in text
    bad = _skin_part(store, T0, 0)
    bad.force_count = np.array([3, 2], np.uint32)
    assert any("force must be" in p for p in EchoTracker().summarize("/x", msgtype, bad, T0)["problems"])


def test_echo_names_the_values_from_the_layout_in_the_bag(tmp_path, store, capsys):
    """Descriptors without their labels (the window node's) are named from the bag's layout topic; without it,
    the summary says so and lists the values by index."""
    from conftest import make_layout

    desc, layout = "tactile_descriptors_msgs/msg/Descriptor", "tactile_descriptors_msgs/msg/DescriptorLayout"
    path = tmp_path / "bag"
    with BagWriter(path) as bag:
        bag.add_topic("/tactile/descriptor", desc)
        bag.add_topic("/tactile/descriptor_layout", layout)
        bag.write("/tactile/descriptor_layout", T0, make_layout(store, T0))
        for k in range(2):
            bag.write("/tactile/descriptor", T0 + (k + 1) * 10**9, make_descriptor(store, T0 + k * 10**9, inline=False))
    assert main(["echo", "/tactile/descriptor", "--bag", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["count"] == 2 and out["type"] == desc  # the layout is read, not shown
    assert out["messages"][0]["body_parts"]["index"]["values"] == {"A_pac": 1500.0, "M_pac": 310.5}
    assert not out["messages"][0]["problems"]
    alone = EchoTracker(type_constants(store)).summarize("/d", desc, make_descriptor(store, T0, inline=False), T0)
    assert alone["problems"][0].startswith(f"layout {alone['layout_id']!r} not seen")
    assert alone["values"] == {"value_0": 0.0, "value_1": 1500.0, "value_2": 310.5}
