"""`tactile urdf` output read by independent URDF parsers; the shipped rviz2 configurations."""

from __future__ import annotations

import subprocess
import sys

import pytest
import yaml

from tactile_descriptors_ros.core.robot import config_dir, load_robot
from tactile_descriptors_ros.core.urdf import urdf_text
from tactile_descriptors_ros.view.rviz import RVIZ_QOS, rviz_text

ROBOTS = ("shadow_hand", "nao")


@pytest.mark.parametrize("name", ROBOTS)
def test_standalone_urdf_parses_and_names_every_frame(name):
    urdf = pytest.importorskip("urdf_parser_py.urdf")
    robot = load_robot(name)
    model = urdf.URDF.from_xml_string(urdf_text(robot).encode())
    assert model.get_root() == robot.geometry.root_frame
    assert {link.name for link in model.links} == robot.geometry.frame_names(robot)
    for f in robot.geometry.frames(robot):
        joint = model.joint_map[f"{f.child}_joint"]
        assert (joint.parent, joint.child, joint.type) == (f.parent, f.child, "fixed")
        assert joint.origin.xyz == pytest.approx(list(f.pose.xyz), abs=1e-9)


@pytest.mark.parametrize("name", ROBOTS)
def test_xacro_macro_expands_onto_the_robots_links(name, tmp_path):
    xacro = pytest.importorskip("xacro")
    urdf = pytest.importorskip("urdf_parser_py.urdf")
    robot = load_robot(name)
    geo = robot.geometry
    (tmp_path / "tactile.xacro").write_text(urdf_text(robot, xacro=True))
    # the robot's own URDF, as far as the macro needs it: its links (prefixed, as Shadow's rh_)
    links = "".join(f'<link name="rh_{lp.name}"/><joint name="rh_{lp.name}_j" type="fixed"><parent link="rh_'
                    f'{lp.parent}"/><child link="rh_{lp.name}"/></joint>' for lp in geo.links)
    (tmp_path / "robot.xacro").write_text(
        f'<?xml version="1.0"?><robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        f'<link name="rh_{geo.root_frame}"/>{links}<xacro:include filename="tactile.xacro"/>'
        f'<xacro:{name}_tactile prefix="rh_"/></robot>')
    doc = xacro.process_file(str(tmp_path / "robot.xacro")).toxml()
    model = urdf.URDF.from_xml_string(doc.encode())
    assert {link.name for link in model.links} == {f"rh_{f}" for f in geo.frame_names(robot)}
    assert model.get_root() == f"rh_{geo.root_frame}"


def test_urdf_command_writes_the_file(tmp_path):
    out = tmp_path / "nao.urdf"
    run = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "urdf", "nao", "-o", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert out.read_text() == urdf_text(load_robot("nao"))


@pytest.mark.parametrize("name", ROBOTS)
def test_shipped_rviz_config_is_the_generated_one_and_names_published_topics(name):
    shipped = (config_dir() / "rviz" / f"{name}.rviz").read_text()
    robot = load_robot(name)
    assert shipped == rviz_text(robot), f"regenerate: tactile rviz {name} -o config/rviz/{name}.rviz"
    cfg = yaml.safe_load(shipped)
    vm = cfg["Visualization Manager"]
    assert vm["Global Options"]["Fixed Frame"] == robot.geometry.root_frame
    topics = {d["Topic"]["Value"]: d["Class"] for d in vm["Displays"] if "Topic" in d}
    for part in robot.body_parts:
        assert topics[f"/tactile/{part.name}/markers"] == "rviz_default_plugins/MarkerArray"
        assert topics[f"/tactile/{part.name}/image"] == "rviz_default_plugins/Image"
    assert all(d["Topic"][k] == v for d in vm["Displays"] if "Topic" in d for k, v in RVIZ_QOS.items())
