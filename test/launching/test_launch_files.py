"""launch/*.launch.py build exactly graph.py's NodeSpecs as launch_ros Node actions, for every argument
combination (launch and launch_ros stubbed, so this runs without them; test_ros2_launch.py runs the files
under the real ros2 launch)."""

from __future__ import annotations

import importlib.util
import sys
import types

import pytest

from tactile_descriptors_ros.launching.graph import build_graph


class _Config:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


def _stubs(monkeypatch):
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
    subs = types.ModuleType("launch.substitutions")
    subs.LaunchConfiguration = _Config
    launch_ros = types.ModuleType("launch_ros")
    ros_actions = types.ModuleType("launch_ros.actions")
    ros_actions.Node = record("node")
    for name, mod in {"launch": launch, "launch.actions": actions, "launch.substitutions": subs,
                      "launch_ros": launch_ros, "launch_ros.actions": ros_actions}.items():
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
    assert set(args) == {"robot", "sim", "sim_speed", "split_window_nodes", "model_path", "use_sim_time", "namespace"}
    context = dict(args, sim=f"demo_{robot}" if sim else "", split_window_nodes=split,
                   sim_speed="0.04" if sim else "")
    opaque = made["opaque"][0]
    assert opaque in ld.actions
    nodes = opaque.kwargs["function"](context)
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
