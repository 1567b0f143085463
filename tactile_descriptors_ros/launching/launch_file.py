"""The body of ``launch/<robot>.launch.py``: one ROS 2 launch description per robot.

``launch`` and ``launch_ros`` are imported only when
:func:`launch_description_for` is called (by ``ros2 launch``), so importing
this module needs neither.  The nodes come from
:func:`tactile_descriptors_ros.launching.graph.build_graph`, the same function
the in-repo launcher (``tactile launch <robot>``) uses.
"""

from __future__ import annotations

from typing import Any

from ..errors import ConfigError
from .graph import build_graph

__all__ = ["LAUNCH_ARGUMENTS", "launch_description_for"]

#: launch arguments besides ``robot``: (name, default, description)
LAUNCH_ARGUMENTS: tuple[tuple[str, str, str], ...] = (
    ("sim", "", "scene name or path: run the drivers on simulated sensors"),
    ("sim_speed", "", "simulated seconds per wall second with sim ('' = the robot's sim_parameters, else 1.0); "
                      "a machine too busy for real time needs less"),
    ("split_window_nodes", "false", "one window node per body part (pooled descriptors)"),
    ("model_path", "", "classifier model file ('' = the nodes: section's)"),
    ("use_sim_time", "false", "use /clock (bag replay)"),
    ("namespace", "", "namespace of the nodes"),
)


def _true(text: str) -> bool:
    return text.strip().lower() in ("1", "true", "yes", "on")


def _nodes(context: Any, *args: Any, **kwargs: Any) -> list:
    """``OpaqueFunction`` body: the launch arguments -> one ``launch_ros`` ``Node`` per NodeSpec."""
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    model_path = LaunchConfiguration("model_path").perform(context)
    speed = LaunchConfiguration("sim_speed").perform(context).strip()
    try:
        sim_speed = float(speed) if speed else None
    except ValueError:
        raise ConfigError(f"must be a number, got {speed!r}", key="sim_speed") from None
    specs = build_graph(
        LaunchConfiguration("robot").perform(context),
        sim_scene=LaunchConfiguration("sim").perform(context) or None,
        sim_speed=sim_speed,
        split_window_nodes=_true(LaunchConfiguration("split_window_nodes").perform(context)),
        model_path=model_path or None,
        use_sim_time=_true(LaunchConfiguration("use_sim_time").perform(context)),
        namespace=LaunchConfiguration("namespace").perform(context),
    )
    return [
        Node(package=s.package, executable=s.executable, name=s.name, namespace=s.namespace,
             parameters=[s.parameters], remappings=list(s.remappings), output="screen")
        for s in specs
    ]


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
