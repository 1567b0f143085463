"""Launch the nao tactile graph: drivers, window node(s), classifier.

    ros2 launch tactile_descriptors_ros nao.launch.py [sim:=demo_nao] [sim_speed:=0.5] [split_window_nodes:=true]
        [model_path:=/path/model.json] [use_sim_time:=true]

Thin over the robot description's ``nodes:`` section: see
:func:`tactile_descriptors_ros.launching.launch_file.launch_description_for`.
"""

from tactile_descriptors_ros.launching.launch_file import launch_description_for


def generate_launch_description():
    return launch_description_for("nao")
