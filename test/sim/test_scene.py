"""Scenes: strict validation naming the key, deterministic resolution, shipped scenes."""

from __future__ import annotations

import copy

import pytest

from tactile_descriptors_ros.errors import SceneError
from tactile_descriptors_ros.sim.scene import large_object_parameters, load_scene, parse_scene, scenes_dir

BASE = {
    "scene": {"name": "t", "robot": "shadow_hand", "seed": 3},
    "effects": {"normal_force": {}, "texture_vibration": {}},
    "defaults": {"force_n": {"grid": [0.2, 3.0, 0.4]}, "speed_m_s": {"grid": [0.005, 0.04, 0.005]},
                 "duration_s": {"grid": [2, 10, 1]}},
    "explorations": [{"materials": ["cork", "steel"], "repeat": 4, "order": "shuffled"}],
}


def _with(path, value):
    data = copy.deepcopy(BASE)
    node = data
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return data


def test_resolution_is_deterministic_and_follows_the_grids():
    a = parse_scene(BASE)
    b = parse_scene(BASE)
    assert [e.to_dict() for e in a.explorations] == [e.to_dict() for e in b.explorations]
    c = parse_scene(BASE, seed=4)
    assert [e.to_dict() for e in a.explorations] != [e.to_dict() for e in c.explorations]
    assert len(a.explorations) == 8
    for e in a.explorations:
        assert round((e.force_n - 0.2) / 0.4, 9) == int(round((e.force_n - 0.2) / 0.4))
        assert 0.2 <= e.force_n <= 3.0 and 2 <= e.duration_s <= 10
        assert e.duration_s == int(e.duration_s)
    assert sorted(e.label for e in a.explorations) == ["cork"] * 4 + ["steel"] * 4


@pytest.mark.parametrize(
    ("path", "value", "key"),
    [
        (("scene", "colour"), "red", "scene.colour"),
        (("scene", "robot"), "r2d2", "scene.robot"),
        (("effects", "wind"), {}, "effects.wind"),
        (("effects", "texture_vibration"), {"gian": 1}, "effects.texture_vibration.gian"),
        (("effects", "dropped_frames"), {"probability": 2}, "effects.dropped_frames.probability"),
        (("effects", "unplug"), {"events": [{"cell": 99, "at_s": 1, "for_s": 1}]}, "effects.unplug.events[0].cell"),
        (("defaults", "force"), 1.0, "defaults.force"),
        (("defaults", "force_n"), {"grid": [3.0, 0.2, 0.4]}, "explorations[0].force_n.grid"),
        (("defaults", "speed_m_s"), -1, "explorations[0].speed_m_s"),
        (("explorations", 0, "body_parts"), ["index", "toe"], "explorations[0].body_parts[1]"),
        (("explorations", 0, "motion"), "lateral+wiggle", "explorations[0].motion"),
        (("explorations", 0, "repeat"), 0, "explorations[0].repeat"),
        (("explorations", 0, "weight_g"), 500, "explorations[0].weight_g"),
        (("explorations", 0, "label"), "x", "explorations[0].label"),
        (("sensors",), {"skin_cell": {}}, "sensors.skin_cell"),
        (("sensors",), {"biotac": {"baseline_pak": 1}}, "sensors.biotac.baseline_pak"),
    ],
)
def test_errors_name_the_key(path, value, key):
    with pytest.raises(SceneError) as info:
        parse_scene(_with(path, value))
    assert info.value.key == key
    assert f"'{key}'" in str(info.value)


def test_missing_explorations_and_bad_parity_on_skin():
    data = copy.deepcopy(BASE)
    del data["explorations"]
    with pytest.raises(SceneError, match="explorations"):
        parse_scene(data)
    nao = _with(("scene", "robot"), "nao")
    nao["effects"]["bad_parity"] = {}
    with pytest.raises(SceneError) as info:
        parse_scene(nao)
    assert info.value.key == "effects.bad_parity"


def test_random_finger_subsets():
    data = _with(("explorations", 0, "body_parts"), {"random_subset": ["thumb", "index", "middle", "ring", "little"]})
    scene = parse_scene(data)
    subsets = {e.body_parts for e in scene.explorations}
    assert len(subsets) > 1
    assert all(1 <= len(s) <= 5 for s in subsets)


def test_large_objects_follow_the_weight():
    f5, v5, t5 = large_object_parameters(500)
    f15, v15, t15 = large_object_parameters(1500)
    assert (f5, large_object_parameters(1000)[0], f15) == (2.0, 2.7, 3.5)
    assert v15 > v5 and t15 < t5
    data = {"scene": {"name": "lo", "robot": "nao"}, "effects": {"normal_force": {}},
            "explorations": [{"material": "param:box", "motion": "large_object", "weight_g": 1500, "body_parts": "all"}]}
    e = parse_scene(data).explorations[0]
    assert e.force_n == 3.5 and e.part_force_n["chest"] < e.force_n
    del data["explorations"][0]["weight_g"]
    with pytest.raises(SceneError) as info:
        parse_scene(data)
    assert info.value.key == "explorations[0].weight_g"


def test_sequences_and_in_hand():
    data = {"scene": {"name": "s", "robot": "shadow_hand"},
            "explorations": [{"material": "cork", "motion": "lateral+medial+circular"},
                             {"material": "cork", "motion": "in_hand", "body_parts": ["index", "middle"],
                              "holding_parts": ["thumb", "ring", "little"]}]}
    s = parse_scene(data)
    assert s.explorations[0].motion == ("lateral", "medial", "circular")
    assert s.explorations[1].part_force_n["thumb"] == 1.5
    data["explorations"][1]["holding_parts"] = ["index"]
    with pytest.raises(SceneError, match="both hold and slide"):
        parse_scene(data)


def test_every_shipped_scene_loads():
    """Every shipped scene validates (protocol scenes with their repeats capped: resolving 12 000 touches is slow)."""
    import yaml

    paths = sorted(scenes_dir().glob("*.yaml"))
    assert {"demo_shadow_hand", "demo_nao"} <= {p.stem for p in paths}
    for path in paths:
        data = yaml.safe_load(path.read_text())
        full = sum(e.get("repeat", 1) for e in data["explorations"])
        for e in data["explorations"]:
            e["repeat"] = min(e.get("repeat", 1), 2)
        scene = parse_scene(data, source=str(path))
        assert scene.explorations, path
        assert full >= len(scene.explorations) / 120


def test_protocol_scenes_follow_the_paper():
    train = load_scene("shadow_hand_lateral_train")
    assert len(train.explorations) == 120 * 20
    assert {e.duration_s for e in train.explorations} == {2.0}
    assert len({e.material for e in train.explorations}) == 120


def test_demo_scenes_last_about_a_minute():
    for name in ("demo_shadow_hand", "demo_nao"):
        assert 55 <= load_scene(name).duration_s <= 95


def test_nao_demo_scene_scores_twenty_explorations_with_several_per_class():
    """The demo scores every exploration but the first of its class: 20 of them, 5 per material."""
    from collections import Counter

    counts = Counter(e.label for e in load_scene("demo_nao").explorations)
    scored = {label: n - 1 for label, n in counts.items()}
    assert sum(scored.values()) >= 20
    assert sorted(n for n in scored.values() if n)[0] >= 5 and sum(1 for n in scored.values() if n) >= 4
