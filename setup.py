"""Install tactile_descriptors_ros (ament_python; also plain pip)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_descriptors_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, PACKAGE + ".*"]),
    package_data={PACKAGE: ["sim/models/*.json", "view/static/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/config", glob("config/*.yaml") + glob("config/*.xml")),
        ("share/" + PACKAGE + "/config/scenes", glob("config/scenes/*.yaml")),
        ("share/" + PACKAGE + "/config/rocket", glob("config/rocket/*.json")),
        ("share/" + PACKAGE + "/config/rviz", glob("config/rviz/*.rviz")),
        ("share/" + PACKAGE + "/launch", glob("launch/*.launch.py")),
    ],
    # What the robot needs (drivers, window node, classifier, bags, the tactile CLI). The
    # evaluation, import, benches, fuzzing and reports are the lab package beside it (lab/).
    install_requires=["numpy", "scipy", "PyYAML", "python-can", "pyserial", "rosbags", "tqdm"],
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="tactile_descriptors_ros maintainers",
    maintainer_email="tactile@example.org",
    description="Robust tactile descriptors and online material recognition for ROS 2",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "tactile = tactile_descriptors_ros.tools.cli:main",
            "biotac_driver = tactile_descriptors_ros.nodes.entry:biotac_driver",
            "skin_driver = tactile_descriptors_ros.nodes.entry:skin_driver",
            "window_node = tactile_descriptors_ros.nodes.entry:window_node",
            "classifier_node = tactile_descriptors_ros.nodes.entry:classifier_node",
            "contact_node = tactile_descriptors_ros.nodes.entry:contact_node",
            "tf_publisher = tactile_descriptors_ros.nodes.entry:tf_publisher",
        ],
    },
)
