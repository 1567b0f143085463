"""Launch-time parameter checks: the table matches the nodes, --set is checked and widened, a dead node stops
the graph."""

from __future__ import annotations

import json

import pytest

from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.launching.graph import build_graph
from tactile_descriptors_ros.launching.parameters import check_parameters
from tactile_descriptors_ros.tools.cli import main


def test_integer_for_a_double_is_widened_and_other_types_refused():
    specs = build_graph("shadow_hand", overrides={"window_node": {"window": {"length_s": 3}}})
    value = next(s for s in specs if s.name == "window_node").parameters["window.length_s"]
    assert value == 3.0 and isinstance(value, float)
    with pytest.raises(ConfigError, match=r"window_node\.window\.length_s.*double"):
        build_graph("shadow_hand", overrides={"window_node": {"window.length_s": "long"}})
    with pytest.raises(ConfigError, match=r"classifier_node\.label_horizon.*integer"):
        build_graph("shadow_hand", overrides={"classifier_node": {"label_horizon": 2.5}})


def test_unknown_parameter_is_an_error_naming_it():
    with pytest.raises(ConfigError, match=r"window_node\.bogus.*window_node has no parameter 'bogus'"):
        build_graph("nao", overrides={"window_node": {"bogus": 1}})
    with pytest.raises(ConfigError, match="did you mean window.length_s"):
        check_parameters("w", "window_node", {"window.lenght_s": 1.0})


def test_shipped_graphs_pass_the_check():
    for robot in ("shadow_hand", "nao"):
        for split in (False, True):
            assert build_graph(robot, sim_scene=f"demo_{robot}", split_window_nodes=split, sim_speed=0.5)


def test_print_checks_the_sets(capsys):
    assert main(["launch", "shadow_hand", "--set", "window_node.bogus=1", "--print"]) == 2
    assert "window_node.bogus" in capsys.readouterr().err
    assert main(["launch", "shadow_hand", "--set", "window_node.window.length_s=3", "--print", "--json"]) == 0
    nodes = {n["name"]: n for n in json.loads(capsys.readouterr().out)["nodes"]}
    assert nodes["window_node"]["parameters"]["window.length_s"] == 3.0


def test_sim_speed_reaches_the_drivers_and_must_be_positive(capsys):
    specs = build_graph("nao", sim_scene="demo_nao", sim_speed=0.04)
    assert next(s for s in specs if s.executable == "skin_driver").parameters["sim.speed"] == 0.04
    with pytest.raises(ConfigError, match="sim_speed"):
        build_graph("nao", sim_scene="demo_nao", sim_speed=0.0)
    with pytest.raises(SystemExit):
        main(["launch", "nao", "--sim", "demo_nao", "--sim-speed", "-1", "--print"])
    assert "--sim-speed" in capsys.readouterr().err


@pytest.mark.ros
def test_launch_stops_the_graph_when_a_node_dies(capsys, monkeypatch, tmp_path):
    """The BioTac driver cannot open its Cheetah adapter (none here) and exits; the launcher then stops the
    window and classifier nodes and exits non-zero, long before its duration."""
    import random

    monkeypatch.setenv("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    # the classifier locks its default model folder under $ROS_HOME: a shared ~/.ros held by another
    # graph would make it exit first
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    code = main(["launch", "shadow_hand", "--json", "--duration-s", "300",
                 "--set", "classifier_node.load_model=false", "--set", "classifier_node.save_after_update=false"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 1
    assert out["died"] == ["biotac_driver"] and out["exit_codes"]["biotac_driver"] == 2
    # the others were stopped by the launcher (SIGINT), not left running until the duration
    assert out["exit_codes"]["window_node"] is not None and out["exit_codes"]["classifier_node"] is not None


@pytest.mark.ros
def test_launched_window_node_takes_an_integer_and_is_tuned_over_the_graph(tmp_path):
    """``tactile launch``'s way of starting a node (parameters file, subprocess), then the parameter services
    over DDS as ``ros2 param`` uses them: the integer given for a double, the range, a set and a refusal."""
    import random
    import time

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    specs = [s for s in build_graph("shadow_hand", overrides={"window_node": {"window.length_s": 3}})
             if s.name == "window_node"]
    domain = random.randint(1, 100)
    env = localhost_environment()
    env["ROS_DOMAIN_ID"] = str(domain)
    procs = GraphProcesses(specs, env=env, output=None, workdir=tmp_path)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("param_probe", context=context)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    client = AsyncParameterClient(node, "/window_node")

    def wait(future, timeout_s=30.0):
        deadline = time.monotonic() + timeout_s
        while not future.done() and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        assert future.done(), "no answer from the window node's parameter services"
        return future.result()

    procs.start()
    try:
        deadline = time.monotonic() + 60
        while not client.services_are_ready() and time.monotonic() < deadline and not procs.exited():
            ex.spin_once(timeout_sec=0.1)
        assert not procs.exited(), {n.spec.name: n.lines[-10:] for n in procs.exited()}
        assert client.services_are_ready(), "the launched window node offers no parameter services"
        got = wait(client.get_parameters(["window.length_s"])).values[0]
        assert got.double_value == 3.0
        desc = wait(client.describe_parameters(["contact.force_threshold_n", "window.mode"])).descriptors
        assert desc[0].floating_point_range[0].from_value == 0.0 and not desc[0].read_only
        assert desc[1].read_only and desc[1].additional_constraints == "one of: fixed, exploration"
        ok = wait(client.set_parameters([Parameter("contact.force_threshold_n", value=0.5)])).results[0]
        assert ok.successful, ok.reason
        bad = wait(client.set_parameters([Parameter("contact.release_threshold_n", value=0.9)])).results[0]
        assert not bad.successful and "release threshold" in bad.reason
        assert wait(client.get_parameters(["contact.force_threshold_n"])).values[0].double_value == 0.5
    finally:
        codes = procs.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert codes["window_node"] is not None
