"""The `tactile fit-textures` command: texture models fitted from the real recordings."""

from __future__ import annotations

import json

import pytest

from tactile_descriptors_ros.tools.cli import main


@pytest.mark.realdata
def test_fit_textures_writes_small_models(biotac_data_dir, tmp_path, capsys):
    assert main(["fit-textures", str(biotac_data_dir), "-o", str(tmp_path), "--trials", "1-3", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert len(summary["materials"]) == 20
    assert all(m["bytes"] < 8000 for m in summary["materials"])
    from tactile_descriptors_ros.sim.textures import load_material

    assert load_material(tmp_path / "cork.json").source["trials"] == [1, 2, 3]


@pytest.mark.realdata
def test_fit_textures_writes_into_the_current_directory_by_default(biotac_data_dir, tmp_path, monkeypatch):
    from tactile_descriptors_ros.sim.textures import models_dir

    shipped = {p.name: p.stat().st_mtime_ns for p in models_dir().glob("*.json")}
    monkeypatch.chdir(tmp_path)
    assert main(["fit-textures", str(biotac_data_dir), "--trials", "1-2", "--json"]) == 0
    written = sorted(p.name for p in (tmp_path / "texture_models").glob("*.json"))
    assert written and {p.name: p.stat().st_mtime_ns for p in models_dir().glob("*.json")} == shipped
