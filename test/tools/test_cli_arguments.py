"""Command-line arguments: replay --clock BAG, record -e repeated, demo --speed, progress."""

from __future__ import annotations

import json

import pytest

from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.tools.cli import build_parser, main
from tactile_descriptors_ros.tools.cmd_replay import clock_option


def _bag(tmp_path):
    from tactile_descriptors_ros.bags.io import BagWriter
    from tactile_descriptors_ros.bags.types import tactile_typestore

    store = tactile_typestore()
    label = "tactile_descriptors_msgs/msg/Label"
    stamp = store.types["builtin_interfaces/msg/Time"](sec=1_700_000_000, nanosec=0)
    header = store.types["std_msgs/msg/Header"](stamp=stamp, frame_id="")
    msg = store.types[label](header=header, exploration_id=1, class_name="cork")
    path = tmp_path / "labels"
    with BagWriter(path) as bag:
        bag.add_topic("/tactile/label", label)
        bag.write("/tactile/label", 1_700_000_000_000_000_000, msg)
    return path


def test_replay_clock_followed_by_the_bag(tmp_path, capsys):
    bag = _bag(tmp_path)
    args = build_parser().parse_args(["replay", "--clock", str(bag)])
    assert clock_option(args.bag, args.clock) == (bag, 100.0)
    args = build_parser().parse_args(["replay", "--clock", "200", str(bag)])
    assert clock_option(args.bag, args.clock) == (bag, 200.0)
    args = build_parser().parse_args(["replay", str(bag), "--clock"])
    assert clock_option(args.bag, args.clock) == (bag, 100.0)
    args = build_parser().parse_args(["replay", str(bag)])
    assert clock_option(args.bag, args.clock) == (bag, None)
    with pytest.raises(ConfigError, match="--clock takes a rate"):
        clock_option(bag, "fast")
    with pytest.raises(ConfigError, match="no bag"):
        clock_option(None, "50")
    assert main(["replay", "--clock", str(bag), "--info", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["message_count"] == 1


def test_record_keeps_every_regex():
    from tactile_descriptors_ros.bags.live import TopicSelector

    args = build_parser().parse_args(["record", "-e", "^/a", "-e", "^/b", "-o", "x"])
    assert args.regex == ["^/a", "^/b"]
    take = TopicSelector(args.topics, regex=args.regex)
    assert take("/a1") and take("/b2") and not take("/c")
    assert TopicSelector(regex="^/a")("/a1")  # one pattern as a string still works


@pytest.mark.parametrize("speed", ["0", "-1", "nan", "inf", "fast"])
def test_demo_speed_must_be_a_positive_number(speed, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["demo", "shadow_hand", "--speed", speed])
    assert exc.value.code == 2 and "--speed" in capsys.readouterr().err


def test_demo_summary_names_touches_never_windowed():
    from types import SimpleNamespace

    from tactile_descriptors_ros.tools.cmd_demo import never_windowed

    touches = [SimpleNamespace(onset_ns=a, release_ns=b) for a, b in ((0, 10), (20, 30), (40, 50))]
    assert never_windowed([(1, 9), (41, 60)], touches) == [1]
    assert never_windowed([(0, 100)], touches) == [1, 2]  # one window over all counts for one touch only
    assert never_windowed([(-5, 12), (19, 31), (45, 46)], touches) == []


def test_number_list_reads_values_in_order_and_skips_empty_items():
    from tactile_descriptors_ros.tools.arguments import number_list

    assert number_list("C values")("0.25,1,,4,") == [0.25, 1.0, 4.0]
    assert number_list("cell counts", integer=True)("100, 1000") == [100, 1000]
    assert number_list("seconds", low_open=False)("1,0") == [1.0, 0.0]
    assert number_list("seconds", high=60)("60") == [60.0]
    assert number_list("cell counts", integer=True, empty=True)("") == []  # `tactile bench --sizes ""`: none


@pytest.mark.parametrize(("kwargs", "text", "message"), [
    ({}, "", "at least one"),
    ({}, "1,x", "joined by ','"),
    ({"integer": True}, "1.5", "joined by ','"),
    ({}, "0", r"lie in \(0, inf\)"),
    ({}, "nan", r"lie in \(0, inf\)"),
    ({}, "inf", r"lie in \(0, inf\)"),
    ({"low_open": False}, "-1", r"lie in \[0, inf\)"),
    ({"high": 60}, "61", r"lie in \(0, 60\]"),
])
def test_number_list_refuses_what_is_not_a_value_in_range(kwargs, text, message):
    import argparse

    from tactile_descriptors_ros.tools.arguments import number_list

    with pytest.raises(argparse.ArgumentTypeError, match=message):
        number_list("values", **kwargs)(text)


@pytest.mark.parametrize(("argv", "message"), [
    (["bench", "--sizes", "0"], "argument --sizes: cell counts must lie in"),
    (["bench", "--lengths", "2,120"], "argument --lengths: window lengths in seconds must lie in"),
])
def test_bench_lists_are_refused_in_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err
