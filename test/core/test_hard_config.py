"""Misconfiguration fails at start, with a message that names the offending key."""

from __future__ import annotations

import copy

import pytest
import yaml

from tactile_descriptors_ros.codecs.biotac_spi import FramePattern
from tactile_descriptors_ros.core.robot import load_robot, parse_robot, robot_config_path
from tactile_descriptors_ros.core.windowing import Windower
from tactile_descriptors_ros.errors import ConfigError, SceneError, TransportUnavailableError
from tactile_descriptors_ros.sim.scene import parse_scene
from tactile_descriptors_ros.transports import create_transport

SHADOW_YAML = yaml.safe_load(robot_config_path("shadow_hand").read_text())


def _shadow() -> dict:
    return copy.deepcopy(SHADOW_YAML)


def _fails(data: dict, key: str, words: str) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        parse_robot(data, source="hard.yaml")
    assert info.value.key == key
    assert f"'{key}'" in str(info.value) and "hard.yaml" in str(info.value)
    assert words in str(info.value)
    return info.value


def test_unknown_body_part_in_node_section():
    d = _shadow()
    d["nodes"]["window_node"]["body_parts"].append("pinky")
    err = _fails(d, "nodes.window_node.body_parts", "unknown body part 'pinky'")
    assert "thumb" in str(err)  # lists the known ones


def test_unknown_body_part_lookup_names_the_known_ones():
    with pytest.raises(ConfigError, match=r"'body_parts'.*unknown body part 'pinky' \(known: thumb, index"):
        load_robot("shadow_hand").body_part("pinky")


def test_cell_listed_in_two_body_parts():
    d = _shadow()
    d["body_parts"][2]["cells"][0]["id"] = 0
    _fails(d, "body_parts[2].cells[0].id", "already listed in body part 'thumb'")


def test_body_part_with_unknown_cell_type():
    d = _shadow()
    d["body_parts"][1]["cell_type"] = "biotac_sp"
    _fails(d, "body_parts[1].cell_type", "unknown cell type 'biotac_sp'")


@pytest.mark.parametrize("rate,words", [(0, "positive"), (-2200.0, "positive"), (float("nan"), "finite"),
                                        (float("inf"), "finite"), (5e6, "plausible"), ("fast", "expected")])
def test_impossible_vibration_rate(rate, words):
    d = _shadow()
    d["cell_types"]["biotac"]["vibration"]["rate_hz"] = rate
    _fails(d, "cell_types.biotac.vibration.rate_hz", words)


def test_vibration_slower_than_deformation():
    d = _shadow()
    d["cell_types"]["biotac"]["deformation"]["rate_hz"] = 5000.0
    _fails(d, "cell_types.biotac.vibration", "faster")


@pytest.mark.parametrize("key,value,words", [
    ("window.mode", "sliding", "must be one of"),
    ("window.length_s", 0, "positive"),
    ("window.min_duration_s", 20.0, "must not exceed"),
    ("contact.release_threshold_n", 5.0, "hysteresis"),
    ("descriptor.layout", "stacked", "must be one of"),
    ("window.hop", 0.5, "unknown key"),
])
def test_impossible_window_and_contact_settings(key, value, words):
    d = _shadow()
    section, name = key.split(".")
    d.setdefault(section, {})[name] = value
    _fails(d, key, words)


@pytest.mark.parametrize("kwargs,key", [({"length_s": 0.0}, "window.length_s"),
                                        ({"hop_s": float("nan")}, "window.hop_s"),
                                        ({"mode": "rolling"}, "window.mode"),
                                        ({"release_threshold_n": 9.0}, "contact.release_threshold_n")])
def test_windower_rejects_impossible_parameters(kwargs, key):
    with pytest.raises(ConfigError) as info:
        Windower(load_robot("shadow_hand"), **kwargs)
    assert info.value.key == key


@pytest.mark.parametrize("spec,words", [
    ("E1 E2 PDC", "no PAC"),
    ("PAC PDC PAC PDC", "appears twice"),
    ("PAC E1 E2 E3", "E1..E19"),
    ("PAC FOO", "FOO"),
    ("", "empty"),
])
def test_impossible_frame_pattern(spec, words):
    with pytest.raises(ConfigError, match=words) as info:
        FramePattern.parse(spec)
    assert info.value.key == "frame_pattern"


@pytest.mark.parametrize("rate", [0.0, -4400.0, float("nan")])
def test_impossible_word_rate(rate):
    with pytest.raises(ConfigError) as info:
        FramePattern.default().rates(rate)
    assert info.value.key == "word_rate_hz"


def test_infinite_word_rate_is_rejected():
    with pytest.raises(ConfigError):
        FramePattern.default().rates(float("inf"))


def test_missing_cheetah_library_fails_at_open_naming_it():
    t = create_transport("cheetah", module="cheetah_py_not_installed_here")
    with pytest.raises(TransportUnavailableError, match="cheetah_py"):
        t.open()
    assert not t.is_open


def test_unknown_transport_name_lists_the_known_ones():
    with pytest.raises(ConfigError, match=r"unknown transport 'usb3'.*cheetah.*serial") as info:
        create_transport("usb3")
    assert info.value.key == "transport"


def test_transport_with_a_parameter_it_does_not_take():
    with pytest.raises(ConfigError, match="bad parameters for transport 'cheetah'"):
        create_transport("cheetah", baudrate=921600)


def test_scene_unplugging_an_unknown_cell():
    scene = {"scene": {"name": "x", "robot": "shadow_hand", "seed": 1},
             "effects": {"unplug": {"events": [{"cell": 42, "at_s": 1.0, "for_s": 0.5}]}},
             "explorations": [{"materials": ["cork"], "body_parts": "all"}]}
    with pytest.raises(SceneError) as info:
        parse_scene(scene, source="hard_scene.yaml")
    assert info.value.key == "effects.unplug.events[0].cell" and "42" in str(info.value)
