"""Where the cells are: the robot descriptions' geometry, its validation, the TF tree and the flat layouts."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tactile_descriptors_ros.core.geometry import Pose, layout_2d
from tactile_descriptors_ros.core.robot import load_robot, parse_robot, robot_config_path
from tactile_descriptors_ros.errors import ConfigError

ROBOTS = ("shadow_hand", "nao")


def _raw(name: str) -> dict:
    return yaml.safe_load(robot_config_path(name).read_text())


@pytest.mark.parametrize("name", ROBOTS)
def test_every_frame_of_a_shipped_robot_resolves_to_its_root(name):
    robot = load_robot(name)
    geo = robot.geometry
    edges = {f.child: f.parent for f in geo.frames(robot)}
    assert len(edges) == len(geo.frames(robot)), "a frame is published twice"
    for frame in edges:
        seen, cur = set(), frame
        while cur != geo.root_frame:
            assert cur not in seen, f"cycle through {cur}"
            seen.add(cur)
            cur = edges[cur]
    # every cell of every body part has a frame on its body part's link
    for part in robot.body_parts:
        for cell in part.cells:
            assert edges[geo.cell_frames[cell.id]] == geo.part_links[part.name]


def test_shipped_link_names_are_the_robots_own():
    hand = load_robot("shadow_hand").geometry
    assert [hand.part_links[p] for p in ("thumb", "index", "middle", "ring", "little")] == \
        ["thdistal", "ffdistal", "mfdistal", "rfdistal", "lfdistal"]
    nao = load_robot("nao").geometry
    assert nao.root_frame == "base_link"
    assert {nao.part_links[p] for p in ("chest", "left_upper_arm", "left_forearm", "left_hand")} == \
        {"torso", "LBicep", "LForeArm", "l_wrist"}


def test_biotac_sites_cover_its_electrodes_and_pressure():
    robot = load_robot("shadow_hand")
    sites = robot.geometry.sites["biotac"]
    channels = {c for s in sites for c in s.channels}
    assert {f"e{i}" for i in range(1, 20)} | {"pac", "pdc", "tdc", "tac"} <= channels
    tax = robot.geometry.taxels(robot, "index")
    assert tax.kind == "sites" and len(tax) == 19 and tax.frame_id == "ffdistal"
    assert np.allclose(np.linalg.norm(tax.normals, axis=1), 1.0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 1e-3),
       st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3))
@example(normal=[0.0, 1e-9, -0.5], xyz=[0.0, 0.0, 0.0])  # within 1e-8 of -z: once snapped to -z
@example(normal=[0.0, 2.569624494688365e-160, -1.0], xyz=[0.0, 0.0, 0.0])  # |z x n| squared underflows
@example(normal=[5e-324, 5e-324, -1.0], xyz=[0.0, 0.0, 0.0])  # the axis over its denormal length: sqrt(2) long
@example(normal=[-5e-324, 1e-320, 1.0], xyz=[0.0, 0.0, 0.0])
@example(normal=[0.0, 0.0, -2.0], xyz=[0.0, 0.0, 0.0])
@example(normal=[0.0, 0.0, 3.0], xyz=[0.0, 0.0, 0.0])
def test_a_pose_from_a_normal_points_its_z_axis_along_it(normal, xyz):
    pose = Pose.from_normal(xyz, normal)
    n = np.asarray(normal) / np.linalg.norm(normal)
    assert np.allclose(pose.normal, n, atol=1e-9)
    assert np.allclose(pose.apply([0.0, 0.0, 0.0]), xyz)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-3.1, 3.1), min_size=3, max_size=3))
def test_rpy_is_urdfs_fixed_axis_convention(rpy):
    pose = Pose.from_rpy([0, 0, 0], rpy)
    r, p, y = rpy
    rx = Rotation.from_rotvec([r, 0, 0]).as_matrix()
    ry = Rotation.from_rotvec([0, p, 0]).as_matrix()
    rz = Rotation.from_rotvec([0, 0, y]).as_matrix()
    assert np.allclose(pose.rotation.as_matrix(), rz @ ry @ rx, atol=1e-9)
    assert np.allclose(Pose.from_rpy([0, 0, 0], pose.rpy).rotation.as_matrix(), rz @ ry @ rx, atol=1e-9)


def test_composed_poses_map_points_like_matrices():
    a = Pose.from_rpy([0.1, -0.2, 0.3], [0.4, 0.2, -1.0])
    b = Pose.from_normal([0.01, 0.02, 0.0], [0.3, -0.2, 0.9])
    p = np.array([0.005, -0.003, 0.002])
    assert np.allclose((a * b).apply(p), a.apply(b.apply(p)))


def test_a_cell_without_a_pose_names_the_file_the_body_part_and_the_cell():
    data = _raw("nao")
    del data["body_parts"][2]["cells"][3]["xyz"]
    with pytest.raises(ConfigError) as err:
        parse_robot(data, source="config/nao.yaml")
    text = str(err.value)
    assert "config/nao.yaml" in text and "'left_forearm'" in text and "(id 32)" in text and "no pose" in text
    assert err.value.key == "body_parts[2].cells[3]"


def test_two_cells_at_one_spot_are_refused_with_the_key():
    data = _raw("nao")
    data["body_parts"][6]["cells"][5]["xyz"] = list(data["body_parts"][6]["cells"][4]["xyz"])
    with pytest.raises(ConfigError, match="two at one spot") as err:
        parse_robot(data, source="nao.yaml")
    assert err.value.key in ("body_parts[6].cells[5].xyz", "body_parts[6].cells[4].xyz")


def test_a_normal_of_length_zero_is_refused_with_the_key():
    data = _raw("nao")
    data["body_parts"][0]["cells"][0]["normal"] = [0, 0, 0]
    with pytest.raises(ConfigError, match="length zero") as err:
        parse_robot(data, source="nao.yaml")
    assert err.value.key == "body_parts[0].cells[0].normal"


@pytest.mark.parametrize("edit, key, words", [
    (lambda d: d["body_parts"][1].__setitem__("link", "elbow"), "body_parts[1].link", "unknown link"),
    (lambda d: d["geometry"]["links"][1].__setitem__("parent", "nowhere"), "geometry.links[1].parent",
     "unknown parent"),
    (lambda d: d["body_parts"][0]["cells"][0].__setitem__("rpy", [0, 0, 0]), "body_parts[0].cells[0].normal",
     "not both"),
    (lambda d: d["body_parts"][0]["cells"][0].__setitem__("xyz", [0, 0]), "body_parts[0].cells[0].xyz",
     "three numbers"),
])
def test_bad_geometry_is_refused_with_the_key(edit, key, words):
    data = _raw("nao")
    edit(data)
    with pytest.raises(ConfigError, match=words) as err:
        parse_robot(data, source="nao.yaml")
    assert err.value.key == key


def test_a_biotac_electrode_without_a_site_is_refused():
    data = _raw("shadow_hand")
    data["cell_types"]["biotac"]["sites"] = [s for s in data["cell_types"]["biotac"]["sites"] if s["name"] != "e7"]
    with pytest.raises(ConfigError, match="'e7'"):
        parse_robot(data, source="shadow_hand.yaml")


def test_a_robot_without_geometry_has_none_and_a_stray_pose_is_an_error():
    data = _raw("nao")
    bare = copy.deepcopy(data)
    del bare["geometry"]
    for part in bare["body_parts"]:
        del part["link"]
        for cell in part["cells"]:
            for k in ("xyz", "normal"):
                cell.pop(k, None)
    assert parse_robot(bare).geometry is None
    stray = copy.deepcopy(bare)
    stray["body_parts"][0]["cells"][0]["xyz"] = [0, 0, 0]
    with pytest.raises(ConfigError, match="geometry section") as err:
        parse_robot(stray)
    assert err.value.key == "body_parts[0].cells[0]"


@pytest.mark.parametrize("name", ROBOTS)
def test_flat_layouts_keep_every_sensing_point_apart(name):
    robot = load_robot(name)
    for part in robot.body_parts:
        tax = robot.geometry.taxels(robot, part.name)
        flat = layout_2d(tax.positions, tax.normals)
        assert flat.shape == (len(tax), 2)
        d2 = np.linalg.norm(flat[:, None] - flat[None, :], axis=2)
        d3 = np.linalg.norm(tax.positions[:, None] - tax.positions[None, :], axis=2)
        np.fill_diagonal(d2, np.inf)
        np.fill_diagonal(d3, np.inf)
        # unrolling and projecting may shrink distances, never collapse two points (at least 40 % of the 3-D)
        assert d2.min() >= 0.4 * d3.min(), part.name
        assert np.array_equal(flat, layout_2d(tax.positions, tax.normals))  # deterministic


def test_two_sided_hand_is_unrolled_into_two_separate_sides():
    robot = load_robot("nao")
    tax = robot.geometry.taxels(robot, "left_hand")
    flat = layout_2d(tax.positions, tax.normals)
    back = tax.normals[:, 2] > 0
    # one straight line separates the back's cells from the palm's on the layout
    gaps = [max(flat[back, k].min() - flat[~back, k].max(), flat[~back, k].min() - flat[back, k].max())
            for k in (0, 1)]
    assert max(gaps) > 0
