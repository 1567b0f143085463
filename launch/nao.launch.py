"""Launch the nao tactile graph: drivers, window node(s), classifier.

    ros2 launch tactile_descriptors_ros nao.launch.py [sim:=demo_nao] [split_window_nodes:=true]
        [model_path:=/path/model.json] [use_sim_time:=true]

Thin over the robot description's ``nodes:`` section: the nodes come from
:func:`tactile_descriptors_ros.launching.graph.build_graph`, the same
function the in-repo launcher (``tactile launch nao``) uses.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from tactile_descriptors_ros.launching.graph import build_graph

ROBOT = "nao"


def _true(text: str) -> bool:
    return text.strip().lower() in ("1", "true", "yes", "on")


def _nodes(context, *args, **kwargs):
    model_path = LaunchConfiguration("model_path").perform(context)
    specs = build_graph(
        LaunchConfiguration("robot").perform(context),
        sim_scene=LaunchConfiguration("sim").perform(context) or None,
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


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("robot", default_value=ROBOT,
                              description="robot description: shipped name or YAML path"),
        DeclareLaunchArgument("sim", default_value="",
                              description="scene name or path: run the drivers on simulated sensors"),
        DeclareLaunchArgument("split_window_nodes", default_value="false",
                              description="one window node per body part (pooled descriptors)"),
        DeclareLaunchArgument("model_path", default_value="",
                              description="classifier model file ('' = the nodes: section's)"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="use /clock (bag replay)"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the nodes"),
        OpaqueFunction(function=_nodes),
    ])
