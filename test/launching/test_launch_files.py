"""launch/*.launch.py build exactly graph.py's NodeSpecs as launch_ros Node actions, for every argument
combination (launch and launch_ros stubbed, so this runs without them; test_ros2_launch.py runs the files
under the real ros2 launch)."""

from __future__ import annotations

import importlib.util
import sys
import types

import pytest

from tactile_descriptors_ros.core.yamlreader import config_dir
from tactile_descriptors_ros.launching.graph import build_graph
from tactile_descriptors_ros.launching.processes import DDS_PROFILE, DDS_PROFILE_VARIABLES, dds_environment


class _Config:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


def _stubs(monkeypatch, not_on_pypi=None):
    """Stub launch and launch_ros; every node's packages count as installed unless ``not_on_pypi`` says
    otherwise (executable -> package), so the result does not depend on what this machine has."""
    from tactile_descriptors_ros.launching import graph

    monkeypatch.setattr(graph, "NOT_ON_PYPI", dict(not_on_pypi or {}))
    made = {}

    def record(kind):
        def ctor(*args, **kwargs):
            obj = types.SimpleNamespace(kind=kind, args=args, kwargs=kwargs)
            made.setdefault(kind, []).append(obj)
            return obj
        return ctor

    launch = types.ModuleType("launch")
    launch.LaunchDescription = lambda actions: types.SimpleNamespace(actions=actions)
    actions = types.ModuleType("launch.actions")
    actions.DeclareLaunchArgument = record("arg")
    actions.OpaqueFunction = record("opaque")
    actions.RegisterEventHandler = record("handler")
    actions.LogInfo = record("log")
    handlers = types.ModuleType("launch.event_handlers")
    handlers.OnProcessExit = record("on_exit")
    subs = types.ModuleType("launch.substitutions")
    subs.LaunchConfiguration = _Config
    launch_ros = types.ModuleType("launch_ros")
    ros_actions = types.ModuleType("launch_ros.actions")
    ros_actions.Node = record("node")
    for name, mod in {"launch": launch, "launch.actions": actions, "launch.substitutions": subs,
                      "launch.event_handlers": handlers, "launch_ros": launch_ros,
                      "launch_ros.actions": ros_actions}.items():
        monkeypatch.setitem(sys.modules, name, mod)
    return made


@pytest.mark.parametrize("robot", ["shadow_hand", "nao"])
@pytest.mark.parametrize("sim, split", [("", "false"), ("scene", "true")])
def test_launch_file_nodes_match_graph(repo_dir, monkeypatch, robot, sim, split):
    made = _stubs(monkeypatch)
    spec = importlib.util.spec_from_file_location(f"launch_{robot}", repo_dir / "launch" / f"{robot}.launch.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    ld = module.generate_launch_description()
    args = {a.args[0]: a.kwargs["default_value"] for a in made["arg"]}
    assert set(args) == {"robot", "sim", "sim_speed", "split_window_nodes", "drivers", "model_path", "params_file",
                         "log_level", "use_sim_time", "namespace"}
    context = dict(args, sim=f"demo_{robot}" if sim else "", split_window_nodes=split,
                   sim_speed="0.04" if sim else "")
    opaque = made["opaque"][0]
    assert opaque in ld.actions
    actions = opaque.kwargs["function"](context)
    nodes = [a for a in actions if a.kind == "node"]
    # every node watched: one that ends on its own ends the launch
    assert [h.args[0].kwargs["target_action"] for h in actions if h.kind == "handler"] == nodes
    expected = build_graph(robot, sim_scene=context["sim"] or None, split_window_nodes=split == "true",
                           sim_speed=0.04 if sim else None)
    assert len(nodes) == len(expected)
    drivers = [s for s in expected if s.executable in ("biotac_driver", "skin_driver")]
    assert drivers and all(s.parameters.get("sim.speed") == (0.04 if sim else None) for s in drivers)
    for node, s in zip(nodes, expected):
        assert node.kwargs["package"] == "tactile_descriptors_ros"
        assert (node.kwargs["executable"], node.kwargs["name"], node.kwargs["namespace"]) == \
            (s.executable, s.name, s.namespace)
        assert node.kwargs["parameters"] == [s.parameters]
        assert node.kwargs["remappings"] == list(s.remappings)
        assert node.kwargs["ros_arguments"] == ["--log-level", "info"]
        assert node.kwargs["additional_env"] == (dds_environment() or None)


def test_launched_nodes_take_the_shipped_dds_profile_unless_the_user_chose_one(repo_dir, monkeypatch):
    for name in (*DDS_PROFILE_VARIABLES, "RMW_IMPLEMENTATION"):
        monkeypatch.delenv(name, raising=False)
    nodes = [a for a in _launch_actions(repo_dir, monkeypatch, robot="nao") if a.kind == "node"]
    assert nodes and all(n.kwargs["additional_env"] == dict.fromkeys(DDS_PROFILE_VARIABLES,
                                                                      str(config_dir() / DDS_PROFILE))
                         for n in nodes)
    monkeypatch.setenv("FASTDDS_DEFAULT_PROFILES_FILE", "/etc/my_profile.xml")
    nodes = [a for a in _launch_actions(repo_dir, monkeypatch, robot="nao") if a.kind == "node"]
    assert all(n.kwargs["additional_env"] is None for n in nodes)


def _launch_actions(repo_dir, monkeypatch, robot="shadow_hand", not_on_pypi=None, **values):
    made = _stubs(monkeypatch, not_on_pypi)
    spec = importlib.util.spec_from_file_location(f"launch_{robot}", repo_dir / "launch" / f"{robot}.launch.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.generate_launch_description()
    context = {a.args[0]: a.kwargs["default_value"] for a in made["arg"]}
    context.update(values)
    return made["opaque"][0].kwargs["function"](context)


@pytest.mark.parametrize("name, value, match", [
    ("split_window_nodes", "yes_please", r"'split_window_nodes': must be true or false, got 'yes_please'"),
    ("drivers", "no", r"'drivers': must be true or false"),
    ("use_sim_time", "", r"'use_sim_time': must be true or false"),
    ("sim_speed", "fast", r"'sim_speed': must be a number above 0"),
    ("sim_speed", "inf", r"'sim_speed': must be a finite number above 0"),
    ("log_level", "loud", r"'log_level': must be one of debug, info, warn, error, fatal"),
    ("params_file", "/no/such/params.yaml", r"'params_file': no such file"),
])
def test_an_ill_typed_launch_argument_is_an_error_naming_it(repo_dir, monkeypatch, name, value, match):
    from tactile_descriptors_ros.errors import ConfigError

    with pytest.raises(ConfigError, match=match):
        _launch_actions(repo_dir, monkeypatch, **{name: value})


def test_an_unknown_launch_argument_is_an_error_naming_the_valid_ones():
    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.launching.launch_file import check_argument_names

    with pytest.raises(ConfigError, match=r"'model_pth': unknown launch argument; did you mean model_path\? "
                                          r"\(valid: robot, sim, sim_speed, split_window_nodes, drivers, model_path"):
        check_argument_names(["sim", "model_pth"])
    check_argument_names(["robot", "drivers", "launch-prefix"])  # ros2 launch's own are fine


def test_drivers_false_starts_every_node_but_the_drivers(repo_dir, monkeypatch):
    actions = _launch_actions(repo_dir, monkeypatch, robot="nao", drivers="false", log_level="debug")
    nodes = [a for a in actions if a.kind == "node"]
    assert [n.kwargs["executable"] for n in nodes] == ["window_node", "classifier_node", "tf_publisher",
                                                         "contact_node"]
    assert all(n.kwargs["ros_arguments"] == ["--log-level", "debug"] for n in nodes)


def test_a_node_whose_message_package_is_missing_is_left_out_with_a_line_saying_so(repo_dir, monkeypatch):
    actions = _launch_actions(repo_dir, monkeypatch, robot="nao", not_on_pypi={"tf_publisher": "tactile_no_such_msgs"})
    nodes = [a for a in actions if a.kind == "node"]
    assert [n.kwargs["executable"] for n in nodes] == ["skin_driver", "window_node", "classifier_node",
                                                         "contact_node"]
    said = [a.kwargs["msg"] for a in actions if a.kind == "log"]
    assert len(said) == 1 and "tf_publisher" in said[0] and "tactile_no_such_msgs" in said[0], said
