"""The body of ``launch/<robot>.launch.py``: one ROS 2 launch description per robot.

``launch`` and ``launch_ros`` are imported only when
:func:`launch_description_for` is called (by ``ros2 launch``), so importing
this module needs neither.  The nodes come from
:func:`tactile_descriptors_ros.launching.graph.build_graph`, the same function
the in-repo launcher (``tactile launch <robot>``) uses.

The launch arguments are checked before anything starts
(:func:`graph_options`): a value of the wrong kind (``split_window_nodes:=yes_please``)
is an error naming the argument and what it accepts, and, when the file is
the one ``ros2 launch`` was given, an argument it does not declare
(``model_pth:=...``) is an error naming the valid ones.  A node that ends on
its own with a non-zero exit code ends the launch, naming the node and the
code.
"""

from __future__ import annotations

import difflib
import math
import os
import sys
from collections.abc import Iterable, Mapping
from typing import Any

from ..errors import ConfigError, NodeExitedError
from .graph import LOG_LEVELS, build_graph, unrunnable
from .processes import dds_environment

__all__ = ["LAUNCH_ARGUMENTS", "ROS2_LAUNCH_ARGUMENTS", "graph_options", "check_argument_names",
           "launch_description_for"]

#: launch arguments besides ``robot``: (name, default, description)
LAUNCH_ARGUMENTS: tuple[tuple[str, str, str], ...] = (
    ("sim", "", "scene name or path: run the drivers on simulated sensors"),
    ("sim_speed", "", "simulated seconds per wall second with sim ('' = the robot's sim_parameters, else 1.0); "
                      "a machine too busy for real time needs less"),
    ("split_window_nodes", "false", "one window node per body part (pooled descriptors): true or false"),
    ("drivers", "true", "start the device drivers: true or false (false: every other node, "
                        "to replay a bag into them with tactile replay)"),
    ("model_path", "", "classifier model file ('' = the nodes: section's)"),
    ("params_file", "", "a ROS 2 parameters file merged over the graph's parameters (checked like them)"),
    ("log_level", "info", f"log level of every node: {', '.join(LOG_LEVELS)}"),
    ("use_sim_time", "false", "use /clock (bag replay): true or false"),
    ("namespace", "", "namespace of the nodes"),
)
#: arguments ``ros2 launch`` adds itself (from its --launch-prefix options)
ROS2_LAUNCH_ARGUMENTS = ("launch-prefix", "launch-prefix-filter")
_BOOLS = {"true": True, "1": True, "false": False, "0": False}


def _bool(name: str, text: str) -> bool:
    value = _BOOLS.get(text.strip().lower())
    if value is None:
        raise ConfigError(f"must be true or false, got {text!r}", key=name)
    return value


def graph_options(values: Mapping[str, str]) -> dict[str, Any]:
    """The launch arguments' text values -> :func:`~.graph.build_graph` keywords (besides the robot), checked.

    Raises
    ------
    ConfigError
        Keyed by the argument: a boolean that is not true/false (1/0), a
        speed that is not a finite number above 0, a log level not in
        :data:`~.graph.LOG_LEVELS`, a parameters file that does not exist.
    """
    speed_text = values.get("sim_speed", "").strip()
    sim_speed = None
    if speed_text:
        try:
            sim_speed = float(speed_text)
        except ValueError:
            raise ConfigError(f"must be a number above 0, got {speed_text!r}", key="sim_speed") from None
        if not (sim_speed > 0 and math.isfinite(sim_speed)):
            raise ConfigError(f"must be a finite number above 0, got {speed_text!r}", key="sim_speed")
    level = values.get("log_level", "").strip().lower()
    if level and level not in LOG_LEVELS:
        raise ConfigError(f"must be one of {', '.join(LOG_LEVELS)}, got {values['log_level']!r}", key="log_level")
    params_file = values.get("params_file", "").strip()
    if params_file and not os.path.isfile(os.path.expanduser(params_file)):
        raise ConfigError(f"no such file: {params_file!r}", key="params_file")
    return {
        "sim_scene": values.get("sim", "") or None,
        "sim_speed": sim_speed,
        "split_window_nodes": _bool("split_window_nodes", values.get("split_window_nodes", "false")),
        "drivers": _bool("drivers", values.get("drivers", "true")),
        "model_path": values.get("model_path", "") or None,
        "params_file": os.path.expanduser(params_file) if params_file else None,
        "log_level": level,
        "use_sim_time": _bool("use_sim_time", values.get("use_sim_time", "false")),
        "namespace": values.get("namespace", ""),
    }


def check_argument_names(given: Iterable[str]) -> None:
    """Every given launch argument is one the launch files declare (or one ``ros2 launch`` adds).

    Raises
    ------
    ConfigError
        Naming the unknown argument, the closest valid one, and every valid one.
    """
    valid = ["robot", *(name for name, _, _ in LAUNCH_ARGUMENTS)]
    for name in given:
        if name in valid or name in ROS2_LAUNCH_ARGUMENTS:
            continue
        near = difflib.get_close_matches(name, valid, n=1)
        hint = f"; did you mean {near[0]}?" if near else ""
        raise ConfigError(f"unknown launch argument{hint} (valid: {', '.join(valid)})", key=name)


def _cli_arguments(context: Any) -> list[str] | None:
    """The names of the ``name:=value`` arguments ``ros2 launch`` was given, when it was given this launch file
    (None when another launch file includes this one: its arguments are its own)."""
    path = getattr(context.locals, "current_launch_file_path", None) if hasattr(context, "locals") else None
    if not path or not any(os.path.basename(a) == os.path.basename(path) for a in sys.argv):
        return None
    return [a.split(":=", 1)[0] for a in context.argv if ":=" in a]


def _nodes(context: Any, *args: Any, **kwargs: Any) -> list:
    """``OpaqueFunction`` body: the launch arguments -> one ``launch_ros`` ``Node`` per NodeSpec."""
    from launch.actions import LogInfo, RegisterEventHandler
    from launch.event_handlers import OnProcessExit
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    given = _cli_arguments(context)
    if given is not None:
        check_argument_names(given)
    values = {name: LaunchConfiguration(name).perform(context) for name, _, _ in LAUNCH_ARGUMENTS}
    specs = build_graph(LaunchConfiguration("robot").perform(context), **graph_options(values))
    left_out = unrunnable(specs)
    actions: list = [LogInfo(msg=reason) for reason in left_out.values()]
    specs = [s for s in specs if s.name not in left_out]
    dds = dds_environment()  # the shipped Fast DDS profile, unless the user chose one (or another middleware)
    for s in specs:
        node = Node(package=s.package, executable=s.executable, name=s.name, namespace=s.namespace,
                    parameters=[s.parameters], remappings=list(s.remappings), output="screen",
                    ros_arguments=["--log-level", s.log_level] if s.log_level else None,
                    additional_env=dds or None)
        actions += [node, RegisterEventHandler(OnProcessExit(target_action=node, on_exit=_ended(s.name)))]
    return actions


def _ended(name: str):
    """``OnProcessExit`` handler of node ``name``: a non-zero exit while the launch runs ends the launch.

    The error (:class:`~tactile_descriptors_ros.errors.NodeExitedError`) is
    what ``ros2 launch`` prints ("Caught exception in launch: node ... exited
    with code ..."); it then stops the other nodes and exits with code 1.  A
    node that stops with code 0 was asked to (Ctrl-C reaches the nodes and
    the launch together), and nothing is said.
    """
    def on_exit(event: Any, context: Any) -> None:
        if context.is_shutdown or event.returncode == 0:
            return None
        raise NodeExitedError(name, event.returncode)

    return on_exit


def launch_description_for(robot: str):
    """The launch description of ``robot``'s tactile graph: drivers, window node(s), classifier.

    Parameters
    ----------
    robot : str
        Default of the ``robot`` launch argument (shipped name or YAML path).

    Returns
    -------
    launch.LaunchDescription
        The launch arguments (``robot`` and :data:`LAUNCH_ARGUMENTS`) and one
        ``OpaqueFunction`` that builds the nodes from their values.
    """
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    from launch import LaunchDescription

    return LaunchDescription([
        DeclareLaunchArgument("robot", default_value=robot,
                              description="robot description: shipped name or YAML path"),
        *(DeclareLaunchArgument(name, default_value=default, description=description)
          for name, default, description in LAUNCH_ARGUMENTS),
        OpaqueFunction(function=_nodes),
    ])
