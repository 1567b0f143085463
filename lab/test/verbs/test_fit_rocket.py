"""The `tactile fit-rocket` command: the rocket group's transforms fitted from the real recordings."""

from __future__ import annotations

import json
import re

import pytest

from tactile_descriptors_ros.core import rocket
from tactile_descriptors_ros.core.yamlreader import config_dir
from tactile_descriptors_ros.tools.cli import main


@pytest.mark.realdata
def test_shipped_transform_is_what_the_documented_command_writes(biotac_data_dir, tmp_path):
    """``config/rocket/biotac.json`` says (and the docs say) it was written by this command: byte for byte."""
    out = tmp_path / "biotac.json"
    assert main(["fit-rocket", str(biotac_data_dir), "--trials", "1-20", "-o", str(out)]) == 0
    assert out.read_bytes() == (config_dir() / "rocket" / "biotac.json").read_bytes()


@pytest.mark.realdata
def test_sizes_are_options(biotac_data_dir, tmp_path, capsys):
    out = tmp_path / "small.json"
    assert main(["fit-rocket", str(biotac_data_dir), "--trials", "1-2", "-o", str(out), "--vibration-features", "168",
                 "--slow-features", "252", "--vibration-max-dilation", "3", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["features"] == {"vibration": 168, "slow": 252}
    params = rocket.load_parameters(out)
    assert params["vibration"].n_features == 168 and params["slow"].n_features == 252
    assert params["vibration"].dilations.tolist() == [1, 3] == summary["dilations"]["vibration"]
    assert params["slow"].n_channels == 22 and params["vibration"].n_channels == 1
    description = json.loads(out.read_text())["description"]
    assert "trials 1-2" in description and "vibration features 168, slow features 252, vibration max dilation 3" \
        in description


def test_help_gives_the_librarys_default_sizes(capsys):
    """The options' help names the defaults; the library's constants are their one home."""
    from tactile_descriptors_lab.evaluation.rocket_fit import SLOW_FEATURES, VIBRATION_FEATURES, VIBRATION_MAX_DILATION

    with pytest.raises(SystemExit):
        main(["fit-rocket", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for option, default in (("--vibration-features", VIBRATION_FEATURES), ("--slow-features", SLOW_FEATURES),
                            ("--vibration-max-dilation", VIBRATION_MAX_DILATION)):
        assert re.search(rf"{option} \S+ [^-]*\(default {default}\)", text), (option, default)


@pytest.mark.parametrize("option, value", [("--slow-features", "0"), ("--vibration-features", "many"),
                                           ("--vibration-max-dilation", "-1")])
def test_a_bad_size_is_refused_before_reading(option, value, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fit-rocket", str(tmp_path / "no_such_data"), "-o", str(tmp_path / "x.json"), option, value])
    assert exc.value.code == 2
    assert f"argument {option}" in capsys.readouterr().err


@pytest.mark.realdata
def test_fewer_features_than_kernels_is_one_line(biotac_data_dir, tmp_path, capsys):
    out = tmp_path / "x.json"
    assert main(["fit-rocket", str(biotac_data_dir), "--trials", "1", "-o", str(out), "--slow-features", "50"]) == 2
    assert "at least 84 features" in capsys.readouterr().err
    assert not out.exists()
