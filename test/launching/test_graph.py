"""The node graph from the robot descriptions (pure: no rclpy)."""

from __future__ import annotations

import pytest
import yaml

from tactile_descriptors_ros.core.robot import load_robot, robot_config_path
from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.launching.graph import (
    build_graph,
    flatten_parameters,
    parameters_document,
    write_parameters_file,
)
from tactile_descriptors_ros.launching.processes import node_command


def test_shadow_hand_graph():
    specs = build_graph("shadow_hand")
    assert [s.executable for s in specs] == ["biotac_driver", "window_node", "classifier_node", "tf_publisher",
                                             "contact_node"]
    by = {s.executable: s.parameters for s in specs}
    drv = by["biotac_driver"]
    assert drv["transport"] == "cheetah" and drv["cheetah.port"] == -1
    assert drv["robot"] == str(robot_config_path("shadow_hand").resolve())
    assert by["window_node"]["body_parts"] == ["thumb", "index", "middle", "ring", "little"]
    assert by["classifier_node"]["robot"] == drv["robot"]  # the classifier keeps its model per robot
    # on the robot its robot_state_publisher publishes the links; simulated, tf_publisher does
    assert by["tf_publisher"]["publish_links"] is False
    sim = {s.executable: s.parameters for s in build_graph("shadow_hand", sim_scene="touch_shadow_hand")}
    assert sim["tf_publisher"]["publish_links"] is True and "sim.scene" not in sim["tf_publisher"]


def test_sim_scene_switches_drivers_only():
    specs = build_graph("nao", sim_scene="demo_nao", model_path="/tmp/m.json", use_sim_time=True)
    drv = next(s for s in specs if s.executable == "skin_driver").parameters
    assert drv["transport"] == "simulated" and drv["sim.scene"].endswith("config/scenes/demo_nao.yaml")
    win = next(s for s in specs if s.executable == "window_node").parameters
    assert "sim.scene" not in win and win["use_sim_time"] is True
    assert next(s for s in specs if s.executable == "classifier_node").parameters["model_path"] == "/tmp/m.json"


def test_split_window_nodes_interleave_exploration_ids():
    specs = build_graph("nao", split_window_nodes=True)
    wins = [s for s in specs if s.executable == "window_node"]
    assert len(wins) == 7 and wins[0].name == "window_node_left_hand"
    assert {w.parameters["exploration_id_stride"] for w in wins} == {7}
    assert sorted(w.parameters["exploration_id_offset"] for w in wins) == list(range(7))
    assert all(w.parameters["descriptor.layout"] == "pooled" and len(w.parameters["body_parts"]) == 1 for w in wins)


def test_split_with_concat_is_refused():
    robot = load_robot("shadow_hand")
    nodes = dict(robot.nodes)
    nodes["window_node"] = {**nodes["window_node"], "parameters": {"descriptor": {"layout": "concat"}}}
    import dataclasses

    with pytest.raises(ConfigError, match="pooled"):
        build_graph(dataclasses.replace(robot, nodes=nodes), split_window_nodes=True)


@pytest.mark.parametrize("change, key, match", [
    ({"executable": "nonsense"}, "nodes.window_node.executable", "executable must be one of"),
    ({"body_parts": ["elbow"]}, "nodes.window_node.body_parts", "unknown body part 'elbow'"),
    ({"colour": "red"}, "nodes.window_node", "unknown key 'colour'"),
    ({"parameters": {"x": []}}, "nodes.window_node.parameters.x", "empty list"),
])
def test_bad_nodes_section_names_the_file_and_key(tmp_path, change, key, match):
    data = yaml.safe_load(robot_config_path("shadow_hand").read_text())
    data["nodes"]["window_node"].update(change)
    path = tmp_path / "hand.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=match) as info:
        build_graph(path)
    assert info.value.key == key
    assert str(info.value).startswith(f"{path}: '{key}': ")


def test_overrides_and_unknown_target():
    specs = build_graph("shadow_hand", overrides={"window_node": {"qos": {"frames": {"depth": 7}}}})
    assert specs[1].parameters["qos.frames.depth"] == 7
    with pytest.raises(ConfigError, match="no node named"):
        build_graph("shadow_hand", overrides={"nobody": {"a": 1}})


def test_flatten_and_parameters_file(tmp_path):
    assert flatten_parameters({"a": {"b": 1, "c": [1, 2.5]}}) == {"a.b": 1, "a.c": [1.0, 2.5]}
    with pytest.raises(ConfigError):
        flatten_parameters({"a": [1, "x"]})
    specs = build_graph("shadow_hand")
    path = write_parameters_file(specs, tmp_path / "p.yaml")
    doc = yaml.safe_load(path.read_text())
    assert doc == parameters_document(specs)
    assert doc["/biotac_driver"]["ros__parameters"]["frame_pattern"] == "default"
    cmd = node_command(specs[1], path, python="py")
    assert cmd[:3] == ["py", "-m", "tactile_descriptors_ros.nodes.window_node"]
    assert cmd[cmd.index("--params-file") + 1] == str(path) and "__node:=window_node" in cmd


def test_tactile_launch_print_json(capsys):
    import json

    from tactile_descriptors_ros.tools.cli import main

    assert main(["launch", "nao", "--print", "--json", "--split-window-nodes", "--set",
                 "classifier_node.eta=0.5"]) == 0
    out = json.loads(capsys.readouterr().out)
    names = [n["name"] for n in out["nodes"]]
    assert names[0] == "skin_driver" and names[-3:] == ["classifier_node", "tf_publisher", "contact_node"]
    assert len(names) == 11 and out["nodes"][-3]["parameters"]["eta"] == 0.5
    with pytest.raises(ConfigError, match="NODE.PARAMETER"):
        from tactile_descriptors_ros.tools.cmd_launch import parse_set

        parse_set(["eta=1"])


def test_demo_matches_windows_to_scene_explorations_by_overlap():
    from types import SimpleNamespace as T

    from tactile_descriptors_ros.tools.cmd_demo import match_exploration

    timings = [T(onset_ns=1_000, release_ns=3_000), T(onset_ns=5_000, release_ns=8_000)]
    assert match_exploration(900, 3_100, timings) == 0
    assert match_exploration(2_900, 7_000, timings) == 1
    assert match_exploration(3_500, 4_500, timings) is None


def test_demo_chance_is_a_guess_among_the_classes_taught_before_each_scored_prediction():
    from tactile_descriptors_ros.tools.cmd_demo import chance_level

    rows = [{"truth": "a", "first_of_class": True, "classes_known": 0},
            {"truth": "b", "first_of_class": True, "classes_known": 1},
            {"truth": "a", "first_of_class": False, "classes_known": 2},  # a guess between a and b: 1/2
            {"truth": "c", "first_of_class": True, "classes_known": 2},
            {"truth": "b", "first_of_class": False, "classes_known": 3},  # 1/3
            {"truth": "c", "first_of_class": False, "classes_known": 3},  # 1/3
            {"truth": None, "correct": False},  # matched no exploration: not scored
            {"truth": "box", "first_of_class": True, "classes_known": 3}]  # taught, never scored
    assert chance_level(rows) == pytest.approx((1 / 2 + 1 / 3 + 1 / 3) / 3)
    assert chance_level(rows[:2]) is None


def test_params_file_is_merged_and_checked(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({
        "classifier_node": {"ros__parameters": {"eta": 0.25}},
        "/window_node": {"ros__parameters": {"window": {"length_s": 3}}},
        "/**": {"ros__parameters": {"diagnostics_period_s": 2}},
    }))
    specs = {s.name: s for s in build_graph("shadow_hand", params_file=params,
                                            overrides={"classifier_node": {"eta": 0.5}})}
    assert specs["classifier_node"].parameters["eta"] == 0.5  # --set wins over the file
    assert specs["window_node"].parameters["window.length_s"] == 3.0  # widened, as everywhere
    assert {s.parameters["diagnostics_period_s"] for s in specs.values()} == {2.0}
    for doc, match in (({"elbow_node": {"ros__parameters": {"eta": 1.0}}}, "no node 'elbow_node' in the graph"),
                       ({"/**": {"ros__parameters": {"bogus": 1}}}, "no node of the graph declares 'bogus'"),
                       ({"window_node": {"eta": 1.0}}, r"expected \{ros__parameters"),
                       ({"window_node": {"ros__parameters": {"window.length_s": 1e300}}}, "must be within")):
        bad = tmp_path / "bad.yaml"
        bad.write_text(yaml.safe_dump(doc))
        with pytest.raises(ConfigError, match=match):
            build_graph("shadow_hand", params_file=bad)
    with pytest.raises(ConfigError, match="cannot read the parameters file"):
        build_graph("shadow_hand", params_file=tmp_path / "missing.yaml")


def test_without_drivers_and_with_a_log_level():
    specs = build_graph("nao", drivers=False, log_level="warn")
    assert [s.executable for s in specs] == ["window_node", "classifier_node", "tf_publisher", "contact_node"]
    assert node_command(specs[0], "p.yaml")[-2:] == ["--log-level", "warn"]
    with pytest.raises(ConfigError, match="'sim': a simulated scene plays through the drivers"):
        build_graph("nao", drivers=False, sim_scene="demo_nao")
    with pytest.raises(ConfigError, match="'log_level': must be one of"):
        build_graph("nao", log_level="loud")
