"""Robot descriptions: the shipped robots, and misconfiguration that names the key."""

from __future__ import annotations

import copy

import pytest
import yaml

from tactile_descriptors_ros.core.robot import config_dir, load_robot, parse_robot
from tactile_descriptors_ros.errors import ConfigError


def test_shadow_hand_has_five_biotacs_in_paper_order():
    robot = load_robot("shadow_hand")
    assert [p.name for p in robot.body_parts] == ["thumb", "index", "middle", "ring", "little"]
    ct = robot.cell_types["biotac"]
    assert len(ct.deformation.channels) == 19 and ct.vibration.channels == ("pac",)
    assert ct.vibration.rate_hz == 2200.0 and robot.contact.force_threshold_n == 0.2


def test_nao_has_116_cells_in_paper_layout():
    robot = load_robot("nao")
    counts = {p.name: len(p.cells) for p in robot.body_parts}
    assert counts == {"left_hand": 14, "right_hand": 14, "left_forearm": 12, "right_forearm": 12,
                      "left_upper_arm": 16, "right_upper_arm": 16, "chest": 32}
    assert robot.n_cells == 116 and len(robot.cell_index()) == 116


def _nao_dict():
    return yaml.safe_load((config_dir() / "nao.yaml").read_text())


@pytest.mark.parametrize("mutate,key,message", [
    (lambda d: d["body_parts"][1]["cells"].append({"id": 1}), "body_parts[1].cells[14].id",
     "already listed in body part 'left_hand'"),
    (lambda d: d["body_parts"][0].update(cell_type="biotac"), "body_parts[0].cell_type", "unknown cell type"),
    (lambda d: d["cell_types"]["skin_cell"]["vibration"].update(rate_hz=-5), "cell_types.skin_cell.vibration.rate_hz",
     "must be positive"),
    (lambda d: d["cell_types"]["skin_cell"]["vibration"].update(rate_hz=100.0), "cell_types.skin_cell.vibration",
     "faster one"),
    (lambda d: d["window"].update(mode="sliding"), "window.mode", "must be one of"),
    (lambda d: d["descriptor"].update(layout="stacked"), "descriptor.layout", "must be one of"),
    (lambda d: d["contact"].update(force_treshold_n=0.3), "contact.force_treshold_n", "unknown key"),
    (lambda d: d["body_parts"].append(copy.deepcopy(d["body_parts"][0])), "body_parts[7].name", "listed twice"),
    (lambda d: d.update(nodes={"window_node": {"body_parts": ["left_foot"]}}), "nodes.window_node.body_parts",
     "unknown body part 'left_foot'"),
    (lambda d: d["cell_types"]["skin_cell"]["deformation"].update(adc_bits=64),
     "cell_types.skin_cell.deformation.adc_bits", "between 1 and 24"),
])
def test_misconfiguration_fails_with_the_key_named(mutate, key, message):
    data = _nao_dict()
    mutate(data)
    with pytest.raises(ConfigError, match=message) as info:
        parse_robot(data, source="nao.yaml")
    assert info.value.key == key
    assert f"'{key}'" in str(info.value) and "nao.yaml" in str(info.value)


def test_unknown_robot_and_body_part_are_clear_errors():
    with pytest.raises(ConfigError, match="unknown robot 'pepper'.*nao.*shadow_hand"):
        load_robot("pepper")
    with pytest.raises(ConfigError, match="unknown body part 'tail'"):
        load_robot("nao").body_part("tail")


PRESSURE_ONLY = """\
robot: {name: pad, description: a capacitive taxel pad}
cell_types:
  taxel_pad:
    deformation: {symbol: P, rate_hz: 50.0, adc_bits: 12, axes: [{name: m1, channels: [t1, t2, t3]},
                                                                  {name: m2, channels: [t4, t5, t6]}]}
    force: {channels: [t1, t2, t3, t4, t5, t6], n_per_count: 0.001, rate_hz: 50.0}
body_parts:
  - {name: palm, cell_type: taxel_pad, cells: [{id: 1}]}
"""


def test_a_cell_type_without_vibration_senses_pressure_only_and_feeds_the_groups_of_v_alone(tmp_path):
    import numpy as np

    from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window

    (tmp_path / "ok.yaml").write_text(PRESSURE_ONLY + "descriptor: {groups: [paper, levels, statistics]}\n")
    robot = load_robot(tmp_path / "ok.yaml")
    ct = robot.cell_types["taxel_pad"]
    assert not ct.has_vibration and ct.vibration.channels == () and ct.channels == tuple(f"t{i}" for i in range(1, 7))
    n = 100
    t = np.arange(n, dtype=np.int64) * 20_000_000
    rng = np.random.default_rng(1)
    sig = CellSignals(np.zeros((0, n)), t, rng.integers(100, 200, (6, n)), t, np.full(n, 0.5))
    d = describe_window(robot, {1: sig}, layout="concat", groups=robot.descriptor.groups)
    assert d.values.size and np.all(np.isfinite(d.values))
    for group in ("per_channel", "bands"):
        (tmp_path / "bad.yaml").write_text(PRESSURE_ONLY + f"descriptor: {{groups: [paper, {group}]}}\n")
        with pytest.raises(ConfigError, match=f"feature group '{group}' reads the vibration channels, which cell "
                                              "type 'taxel_pad' does not have .pressure only.; the groups it can "
                                              "feed: paper, levels, statistics"):
            load_robot(tmp_path / "bad.yaml")
