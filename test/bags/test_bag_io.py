"""Bags written and read back by rosbags: bytes, type hashes (= rosidl's and rclpy's), QoS, errors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import yaml

from conftest import make_batch, make_descriptor, make_label, make_prediction
from tactile_descriptors_ros.bags.io import BagReader, BagWriter, bag_info, read_messages
from tactile_descriptors_ros.bags.qos import SENSOR_DATA_QOS, adapt_offered_qos, make_qos
from tactile_descriptors_ros.bags.types import TACTILE_TYPES, msg_dir, tactile_typestore
from tactile_descriptors_ros.errors import BagError

T0 = 1_700_000_000_000_000_000


def _write_example_bag(path: Path, store, storage: str) -> list[tuple[str, int, object]]:
    msgs = [
        ("/tactile/index/frames", T0, make_batch(store, T0, 0)),
        ("/tactile/index/frames", T0 + 20_000_000, make_batch(store, T0 + 20_000_000, 2)),
        ("/tactile/descriptor", T0 + 30_000_000, make_descriptor(store, T0 + 30_000_000)),
        ("/tactile/prediction", T0 + 40_000_000, make_prediction(store, T0 + 40_000_000)),
        ("/tactile/label", T0 + 50_000_000, make_label(store, T0 + 50_000_000)),
    ]
    with BagWriter(path, storage=storage) as bag:
        bag.add_topic("/tactile/index/frames", "tactile_descriptors_msgs/msg/BioTacFrameBatch", [SENSOR_DATA_QOS])
        bag.add_topic("/tactile/descriptor", "tactile_descriptors_msgs/msg/Descriptor")
        bag.add_topic("/tactile/prediction", "tactile_descriptors_msgs/msg/Prediction")
        bag.add_topic("/tactile/label", "tactile_descriptors_msgs/Label", [make_qos("reliable", "transient_local", 1)])
        for topic, t, m in msgs:
            bag.write(topic, t, m)
    return msgs


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bag_round_trip(tmp_path, store, storage):
    path = tmp_path / "bag"
    msgs = _write_example_bag(path, store, storage)
    info = bag_info(path)
    assert info.storage == storage and info.version == 8 and info.message_count == len(msgs)
    assert info.start_ns == T0 and info.end_ns == T0 + 50_000_000
    frames = info.topics["/tactile/index/frames"]
    assert frames.message_count == 2
    assert frames.type_hash == store.hash_rihs01("tactile_descriptors_msgs/msg/BioTacFrameBatch")
    assert frames.offered_qos[0].reliability.name == "BEST_EFFORT" and frames.offered_qos[0].depth == 5
    label = info.topics["/tactile/label"]
    assert label.offered_qos[0].durability.name == "TRANSIENT_LOCAL"
    assert "[counts]" in frames.msgdef  # the .msg text with its units travels in the bag
    with BagReader(path) as reader:
        got = list(reader.messages())
        assert [(m.topic, m.log_time_ns) for m in got] == [(t, ts) for t, ts, _ in msgs]
        for m, (_, _, original) in zip(got, msgs):
            assert m.data == bytes(store.serialize_cdr(original, m.msgtype))
            back = reader.deserialize(m)
            assert bytes(store.serialize_cdr(back, m.msgtype)) == m.data
    # topic filter and single-file reading
    assert [m.topic for m in read_messages(path, ["/tactile/label"])] == ["/tactile/label"]
    storage_file = next(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
    assert bag_info(storage_file).message_count == len(msgs)


def test_metadata_is_rosbag2_v8(tmp_path, store):
    """What ros2 bag (Humble..Kilted) parses: v8, QoS as a YAML string with integer policies, hashes."""
    path = tmp_path / "bag"
    _write_example_bag(path, store, "mcap")
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 8 and meta["storage_identifier"] == "mcap"
    for entry in meta["topics_with_message_count"]:
        tm = entry["topic_metadata"]
        assert tm["serialization_format"] == "cdr"
        assert tm["type_description_hash"].startswith("RIHS01_")
        offered = yaml.safe_load(tm["offered_qos_profiles"]) if tm["offered_qos_profiles"] else []
        for q in offered:
            assert isinstance(q["reliability"], int) and isinstance(q["history"], int)


def test_hashes_equal_rosidl_type_descriptions(store):
    """rosbags' computed RIHS01 equals the hash rosidl generated into <pkg>/msg/<Name>.json."""
    share = Path(sys.prefix) / "share" / "tactile_descriptors_msgs" / "msg"
    if not (share / "Label.json").is_file():
        pytest.skip("tactile_descriptors_msgs not built into this prefix")
    for msgtype in TACTILE_TYPES:
        name = msgtype.split("/")[-1]
        desc = json.loads((share / f"{name}.json").read_text())
        expected = {h["type_name"]: h["hash_string"] for h in desc["type_hashes"]}
        assert store.hash_rihs01(msgtype) == expected[msgtype]
        for dep, h in expected.items():  # Header, Time: from the base store
            assert store.hash_rihs01(dep) == h


def test_msg_dir_found():
    assert (msg_dir() / "BioTacFrameBatch.msg").is_file()


def test_bag_with_another_definition_is_decoded_with_its_own(tmp_path):
    """A bag recorded with a different Label layout is decoded with the bag's definition, not ours."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    other = get_typestore(Stores.ROS2_KILTED)
    other.register(get_types_from_msg("std_msgs/Header header\nstring class_name\nfloat64 confidence\n",
                                      "tactile_descriptors_msgs/msg/Label"))
    cls = other.types["tactile_descriptors_msgs/msg/Label"]
    hdr = other.types["std_msgs/msg/Header"](stamp=other.types["builtin_interfaces/msg/Time"](sec=1, nanosec=2),
                                             frame_id="")
    path = tmp_path / "old"
    with BagWriter(path, typestore=other) as bag:
        bag.add_topic("/label", "tactile_descriptors_msgs/msg/Label")
        bag.write("/label", 5, cls(header=hdr, class_name="cork", confidence=0.75))
    ours = tactile_typestore()
    with BagReader(path) as reader:
        assert reader.info.topics["/label"].type_hash != ours.hash_rihs01("tactile_descriptors_msgs/msg/Label")
        msg = reader.deserialize(next(reader.messages()))
    assert msg.class_name == "cork" and msg.confidence == 0.75


def test_writer_errors(tmp_path, store):
    with pytest.raises(BagError, match="storage"):
        BagWriter(tmp_path / "x", storage="rosbag1")
    (tmp_path / "exists").mkdir()
    with pytest.raises(BagError, match="exists"):
        BagWriter(tmp_path / "exists")
    with BagWriter(tmp_path / "b") as bag:
        with pytest.raises(BagError, match="add_topic"):
            bag.write("/nope", 1, b"\x00\x01\x00\x00")
        bag.add_topic("/label", "tactile_descriptors_msgs/msg/Label")
        with pytest.raises(BagError, match="already in the bag"):
            bag.add_topic("/label", "tactile_descriptors_msgs/msg/Prediction")
        with pytest.raises(BagError, match="no definition"):
            bag.add_topic("/x", "no_such_pkg/msg/Thing")
    with pytest.raises(BagError, match="metadata.yaml"):
        BagReader(tmp_path)
    with pytest.raises(BagError, match="no topic"):
        list(read_messages(tmp_path / "b", ["/missing"]))


def test_adapted_qos_follows_rosbag2_rules():
    rel, be = make_qos("reliable"), make_qos("best_effort")
    latched = make_qos("reliable", "transient_local", 1)
    assert adapt_offered_qos([rel, rel]).reliability.name == "RELIABLE"
    assert adapt_offered_qos([rel, be]).reliability.name == "BEST_EFFORT"
    assert adapt_offered_qos([latched]).durability.name == "TRANSIENT_LOCAL"
    assert adapt_offered_qos([latched, rel]).durability.name == "VOLATILE"
    assert adapt_offered_qos([]).reliability.name == "RELIABLE"
    assert adapt_offered_qos([rel._replace(depth=0)], default_depth=33).depth == 33
    assert adapt_offered_qos([rel._replace(depth=7), be._replace(depth=20)]).depth == 20
