"""The node parameter schemas: built checked, one home per parameter, the launch table and the docs from them.

No rclpy: the schemas are plain data (test_node_schemas.py checks the nodes declare exactly them)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tactile_descriptors_ros.core.robot import ContactSpec, WindowSpec, load_robot, parse_robot
from tactile_descriptors_ros.core.windowing import Windower
from tactile_descriptors_ros.errors import ConfigError, SchemaError
from tactile_descriptors_ros.launching.graph import build_graph
from tactile_descriptors_ros.launching.parameters import PARAMETER_TYPES, check_parameters
from tactile_descriptors_ros.params import SCHEMAS
from tactile_descriptors_ros.params.docs import main as docs_main
from tactile_descriptors_ros.params.docs import render
from tactile_descriptors_ros.params.schema import NodeSchema, Param, check_value
from tactile_descriptors_ros.params.window_node import WINDOW_NODE

PACKAGE = Path(__file__).resolve().parents[2] / "tactile_descriptors_ros"


# ------------------------------------------------------------- bad schemas
@pytest.mark.parametrize("params, match", [
    ((Param("gain", "double", "a", default=1.0, range=(0.0, 2.0)),
      Param("gain", "double", "b", default=1.0, range=(0.0, 2.0))), "named twice"),
    ((Param("gain", "double", "a", default=3.0, range=(0.0, 2.0)),), r"default 3\.0 is refused.*within 0 \.\. 2"),
    ((Param("gain", "float", "a", default=1.0),), "unknown type 'float'"),
    ((Param("gain", "double", "a", default=1.0),), "a number needs a finite range"),
    ((Param("gain", "double", "a", default=1.0, range=(0.0, float("inf"))),), "two finite numbers"),
    ((Param("mode", "string", "a", default="fast", choices=("slow",)),), "must be one of slow"),
    ((Param("depth", "integer", "a", default=True, range=(0, 5)),), "expects an integer"),
    ((Param("limit", "double", "a", robot="window.nonsense_s", range=(0.0, 1.0)),), "not a key of the robot"),
    ((Param("limit", "double", "a", robot="window.length_s", range=(0.0, 1.0)),),
     r"robot description's default of window\.length_s 2\.0 is refused"),
    ((Param("band", "double", "a", like="threshold", range=(0.0, 1.0)),), "not declared before it"),
    ((Param("gain", "double", "a", default=1.0, range=(0.0, 2.0), apply="hook"),), "read-only parameter has no apply"),
    ((Param("gain", "double", "", default=1.0, range=(0.0, 2.0)),), "no description"),
    ((Param("2gain", "double", "a", default=1.0, range=(0.0, 2.0)),), "not a valid ROS parameter name"),
    ((Param("gain", "double", "a", range=(0.0, 2.0)),), "exactly one of default, robot, like, derived"),
])
def test_a_bad_schema_is_an_error_naming_the_node_and_the_parameter(params, match):
    with pytest.raises(SchemaError, match=match) as err:
        NodeSchema("probe_node", params)
    assert err.value.key == f"probe_node.{params[-1].name}"
    assert str(err.value).startswith(f"'probe_node.{params[-1].name}': ")


def test_every_shipped_schema_bounds_every_number_and_string():
    for exe, schema in SCHEMAS.items():
        assert schema.executable == exe
        for p in schema:
            if p.item_type in ("integer", "double"):
                assert p.range is not None, (exe, p.name)
            if p.tunable and p.item_type == "string":
                assert p.max_chars <= 4096, (exe, p.name)


# ---------------------------------------------------------------- checking
@pytest.mark.parametrize("value, match", [
    (float("nan"), "finite"), (float("inf"), "finite"), (-float("inf"), "finite"), (1e300, "within"),
    (-1.0, "within"), (2**62, "within"), (1e-300, "within"), ("", "expects a double"), ("x" * 5000, "expects a double"),
    (True, "expects a double"),
])
def test_check_value_refuses_what_the_range_does_not_hold(value, match):
    with pytest.raises(ConfigError, match=match):
        check_value(WINDOW_NODE["window.length_s"], value, node="window_node")


def test_check_value_of_strings_and_lists():
    frame = WINDOW_NODE["frame_id"]
    assert check_value(frame, "base_link") == "base_link"
    for bad, match in (("", "must not be empty"), ("a b", "blanks"), ("x" * 257, "at most 256"),
                       ("a\x00b", "control characters"), (3, "expects a string")):
        with pytest.raises(ConfigError, match=match):
            check_value(frame, bad)
    groups = WINDOW_NODE["descriptor.groups"]
    assert check_value(groups, ["paper"]) == ["paper"]
    with pytest.raises(ConfigError, match="at least one item"):
        check_value(groups, [])
    assert check_value(WINDOW_NODE["qos.frames.reliability"], "RELIABLE") == "reliable"


# ------------------------------------------------------------ one home each
def test_f_t_has_one_name_and_one_default_everywhere():
    """The contact threshold F_t: every node parameter holding it is named contact.force_threshold_n and
    defaults to the robot description's value, whose own default is the one in ContactSpec."""
    holders = {exe: [p for p in s if "threshold" in p.name and "release" not in p.name] for exe, s in SCHEMAS.items()}
    for exe, params in holders.items():
        for p in params:
            assert p.name == "contact.force_threshold_n" and p.robot == "contact.force_threshold_n", (exe, p)
    assert {exe for exe, params in holders.items() if params} == {"window_node", "biotac_driver", "skin_driver",
                                                                  "contact_node"}
    bare = parse_robot(_robot_without_contact())
    assert bare.contact.force_threshold_n == ContactSpec.force_threshold_n
    assert bare.window.length_s == WindowSpec.length_s
    offenders = [str(f.relative_to(PACKAGE)) for f in PACKAGE.rglob("*.py")
                 if re.search(r"\bcontact_threshold_n\b", f.read_text())]
    assert not offenders, offenders


def _robot_without_contact() -> dict:
    import yaml

    from tactile_descriptors_ros.core.robot import robot_config_path

    data = yaml.safe_load(robot_config_path("shadow_hand").read_text())
    for section in ("contact", "window"):
        data.pop(section, None)
    data["descriptor"].pop("block_s", None)
    data["descriptor"].pop("block_hop_s", None)
    return data


def test_the_windower_settings_are_the_schemas_windower_parameters():
    """A window node parameter of the 'windower' hook is a Windower setting of the same last name: no name map."""
    windower = Windower(load_robot("shadow_hand"))
    assert set(windower.settings()) == {n.rsplit(".", 1)[1] for n in WINDOW_NODE.apply_groups()["windower"]}


def test_the_launch_table_is_the_schemas():
    assert PARAMETER_TYPES == {exe: s.types() for exe, s in SCHEMAS.items()}


def test_the_launch_check_applies_the_schema_ranges_and_choices():
    with pytest.raises(ConfigError, match=r"'w\.window\.length_s': must be within 0\.001 \.\. 3600 s"):
        check_parameters("w", "window_node", {"window.length_s": 1e300})
    with pytest.raises(ConfigError, match=r"'w\.window\.mode': must be one of fixed, exploration"):
        check_parameters("w", "window_node", {"window.mode": "sliding"})
    with pytest.raises(ConfigError, match=r"'classifier_node\.label_wait_s': must be a finite number"):
        build_graph("shadow_hand", overrides={"classifier_node": {"label_wait_s": float("inf")}})


# ------------------------------------------------------------------- docs
def test_docs_tables_are_written_from_the_schemas(repo_dir):
    page = repo_dir / "docs" / "nodes.md"
    assert docs_main([str(page), "--check"]) == 0, "run: python -m tactile_descriptors_ros.params.docs docs/nodes.md"
    text = page.read_text()
    for exe, schema in SCHEMAS.items():
        block = text.split(f"<!-- BEGIN parameters {exe} ", 1)[1].split(f"<!-- END parameters {exe} -->", 1)[0]
        for p in schema:
            if not p.name.startswith("qos."):
                assert f"| `{p.name}` |" in block, (exe, p.name)


def test_docs_check_fails_on_a_stale_table(tmp_path, repo_dir):
    page = tmp_path / "nodes.md"
    page.write_text((repo_dir / "docs" / "nodes.md").read_text().replace("| `window.length_s` |", "| `window.len` |"))
    assert docs_main([str(page), "--check"]) == 1
    assert docs_main([str(page)]) == 0
    assert page.read_text() == (repo_dir / "docs" / "nodes.md").read_text()


def test_docs_without_a_nodes_block_is_an_error():
    with pytest.raises(ConfigError, match="no parameter block for .*window_node"):
        render("<!-- BEGIN parameters tunable -->\n<!-- END parameters tunable -->\n", SCHEMAS)
