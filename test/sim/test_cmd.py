"""The `tactile simulate` command."""

from __future__ import annotations

import json

import numpy as np
import yaml

from tactile_descriptors_ros.tools.cli import main

SCENE = {
    "scene": {"name": "cmd", "robot": "shadow_hand", "seed": 2, "lead_in_s": 0.3},
    "effects": {"normal_force": {}, "texture_vibration": {}, "adc": {}},
    "explorations": [{"materials": ["cork", "felt"], "duration_s": 1.0, "pause_s": 0.3, "body_parts": ["index"]}],
}


def test_simulate_writes_npz_and_json_summary(tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(SCENE))
    assert main(["simulate", str(path), "-o", str(tmp_path / "out.npz"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["explorations"] == 2 and summary["outputs"] == [str(tmp_path / "out.npz")]
    z = np.load(tmp_path / "out.npz")
    assert "cell1/pac/counts" in z and json.loads(str(z["ground_truth"]))["explorations"][1]["label"] == "felt"


def test_simulate_wire_bytes(tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(SCENE))
    assert main(["simulate", str(path), "--wire", "bridge", "-o", str(tmp_path / "w.bin"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["wire"]["bytes"] == (tmp_path / "w.bin").stat().st_size > 0
    assert (tmp_path / "w.bin").read_bytes()[:2] == b"\xb1\x4e"


def test_simulate_bad_scene_is_a_clear_error(tmp_path, capsys):
    bad = dict(SCENE, effects={"wind": {}})
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(bad))
    assert main(["simulate", str(path)]) == 2
    assert "effects.wind" in capsys.readouterr().err
