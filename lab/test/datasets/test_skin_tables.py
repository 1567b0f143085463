"""Skin-cell recordings in tables: a mapping names a cell type's channels, and evaluate reads them.

The simulator's skin data (one NAO hand cell: accelerometer x, y, z at 1 kHz,
three force sensors at 250 Hz, proximity, temperature) are written, inside
the test, as CSV, NPZ and HDF5 tables with another lab's column names, read
back through mapping files, and must give the same values; a misnamed
column is named with its file and mapping key.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from writers import write_skin_csv, write_skin_npz

from tactile_descriptors_lab.datasets.layouts import (
    SKIN_CHANNELS,
    SKIN_SAMPLES_PER_FRAME,
    simulated_skin_trials,
    skin_hdf5_mapping,
    write_skin_hdf5,
)
from tactile_descriptors_lab.datasets.mapping import load_mapping
from tactile_descriptors_lab.datasets.readers import LoadReport, read_source
from tactile_descriptors_lab.datasets.recording import CellRecording
from tactile_descriptors_ros.core.groups import selection_labels
from tactile_descriptors_ros.errors import ConfigError, DataFormatError
from tactile_descriptors_ros.tools.cli import main

CSV_MAPPING = {"format": "csv", "files": "*/*.csv", "robot": "nao", "class": {"from": "folder"},
               "trial": {"from": "file", "pattern": r"trial_(\d+)$"}, "channels": SKIN_CHANNELS,
               "stamps": {"column": "t_ns", "unit": "ns"}, "tare": "none"}
HDF5_MAPPING = skin_hdf5_mapping()
NPZ_MAPPING = {"format": "npz", "files": "*.npz", "robot": "nao",
               "class": {"from": "file", "pattern": r"^([a-z]+)_"}, "trial": {"from": "file", "pattern": r"_(\d+)$"},
               "channels": {"ax": "ax", "ay": "ay", "az": "az", "f1": "F1", "f2": "F2", "f3": "F3",
                            "proximity": "proximity", "temperature": "temperature"},
               "stamps": {"column": "stamp", "unit": "ns"}, "tare": "none"}


@pytest.fixture(scope="module")
def trials():
    return simulated_skin_trials()


def _mapping(tmp: Path, name: str, d: dict) -> Path:
    p = tmp / f"{name}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _write(fmt: str, tmp: Path, trials) -> tuple[Path, Path]:
    if fmt == "csv":
        return write_skin_csv(tmp / "csv", trials), _mapping(tmp, "csv", CSV_MAPPING)
    if fmt == "npz":
        return write_skin_npz(tmp / "npz", trials), _mapping(tmp, "npz", NPZ_MAPPING)
    return write_skin_hdf5(tmp / "skin.h5", trials), _mapping(tmp, "h5", HDF5_MAPPING)


@pytest.mark.parametrize("fmt", ["csv", "npz", "hdf5"])
def test_skin_tables_read_back_the_simulated_values(fmt, trials, tmp_path):
    source, mapping = _write(fmt, tmp_path, trials)
    got = read_source(source, mapping)
    want = sorted(trials, key=lambda t: (t["class_name"], t["trial"]))
    assert [(r.class_name, r.trial) for r in got] == [(t["class_name"], t["trial"]) for t in want]
    for r, t in zip(got, want):
        assert isinstance(r, CellRecording) and r.cell_type == "skin_cell"
        assert r.samples_per_frame == SKIN_SAMPLES_PER_FRAME and r.absent == ()
        np.testing.assert_array_equal(r.frame_t_ns, t["t_ns"])
        np.testing.assert_array_equal(r.vibration, t["vibration"])
        np.testing.assert_array_equal(r.deformation, t["force"])
        np.testing.assert_array_equal(r.extra, np.stack([t["proximity"], t["temperature"]]))
        # accelerometer samples spread over each force sample's 4 ms, as the 1 kHz stream they came from
        np.testing.assert_array_equal(r.vibration_t_ns, t["t_ns"][0] + np.arange(r.vibration.shape[1]) * 1_000_000)
        np.testing.assert_allclose(r.force_counts, t["force"].mean(axis=0))


def test_skin_tables_describe_as_the_simulated_cell(trials, tmp_path):
    """A window of the table's trial gives the descriptor of the same window built from the simulator."""
    from tactile_descriptors_lab.evaluation.bank import finger_robot, recording_cells
    from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
    from tactile_descriptors_ros.core.robot import load_robot

    source, mapping = _write("hdf5", tmp_path, trials)
    rec = read_source(source, mapping)[0]
    t = sorted(trials, key=lambda t: (t["class_name"], t["trial"]))[0]
    ct = load_robot("nao").cell_types["skin_cell"]
    robot = finger_robot(ct)
    groups = ("per_channel", "bands", "levels", "statistics")
    w = rec.crop_frames(100, 400)
    got = describe_window(robot, recording_cells(w, ct), groups=groups).values
    k = SKIN_SAMPLES_PER_FRAME
    cell = CellSignals(t["vibration"][:, 100 * k:400 * k], t["t_ns"][0] + np.arange(100 * k, 400 * k) * 1_000_000,
                       t["force"][:, 100:400], t["t_ns"][100:400],
                       t["force"][:, 100:400].mean(axis=0) * ct.force.n_per_count,
                       extra=np.stack([t["proximity"], t["temperature"]])[:, 100:400])
    want = describe_window(robot, {0: cell}, groups=groups).values
    assert got.shape == want.shape and np.isfinite(got).all()
    np.testing.assert_array_equal(got, want)


def test_a_misnamed_skin_column_names_the_file_the_column_and_the_key(trials, tmp_path):
    source = write_skin_csv(tmp_path / "csv", trials[:1])
    bad = {**CSV_MAPPING, "channels": {**SKIN_CHANNELS, "ay": "accel_y{i}"}}
    with pytest.raises(DataFormatError) as err:
        read_source(source, _mapping(tmp_path, "bad", bad))
    msg = str(err.value)
    assert "trial_1.csv" in msg and "accel_y1" in msg and "channels.ay" in msg
    extra = {**CSV_MAPPING, "channels": {**SKIN_CHANNELS, "temperature": "temperature"}}
    with pytest.raises(DataFormatError, match=r"trial_1.csv: no column 'temperature' \(mapping key "
                                              r"channels.temperature\)"):
        read_source(source, _mapping(tmp_path, "extra", extra))


def test_skin_mapping_keys_are_the_cell_types_channels(tmp_path):
    typo = {**CSV_MAPPING, "channels": {**SKIN_CHANNELS, "proximty": "prox"}}
    with pytest.raises(ConfigError, match=r"channels.proximty.*did you mean 'proximity'"):
        load_mapping(_mapping(tmp_path, "typo", typo))
    no_force = {**CSV_MAPPING, "channels": {k: v for k, v in SKIN_CHANNELS.items() if k != "f2"}}
    with pytest.raises(ConfigError, match="channels.f2.*missing channel"):
        load_mapping(_mapping(tmp_path, "noforce", no_force))
    with pytest.raises(ConfigError, match="cell_type.*no cell type 'skin'"):
        load_mapping(_mapping(tmp_path, "ct", {**CSV_MAPPING, "cell_type": "skin"}))
    m = load_mapping(_mapping(tmp_path, "ok", CSV_MAPPING))
    assert m.cell_type == "skin_cell" and m.samples_per_frame == 4  # 1 kHz accelerometer over 250 Hz frames


def test_untared_skin_force_is_tared_per_trial(trials, tmp_path):
    """A force offset of 200 counts (0.49 N, above F_t) at rest is detected; the counts stay as recorded."""
    source = write_skin_csv(tmp_path / "csv", trials, force_offset=200)
    report = LoadReport(str(source), "")
    got = read_source(source, _mapping(tmp_path, "auto", {**CSV_MAPPING, "tare": "auto"}), report=report)
    assert len(report.tared) == len(trials) and "resting force" in report.tare_lines()[0]
    for r in got:
        assert r.deformation.min() >= 200  # raw counts untouched
        assert np.all(r.deformation_tare > 200) and np.all(r.deformation_tare < 240)
        rest = r.force_n(0.002442)[:50]  # before the touch
        assert np.all(np.abs(rest) < 0.05)
        assert r.force_n(0.002442).max() > 1.0  # the 2 N touch
    plain = read_source(write_skin_csv(tmp_path / "plain", trials), _mapping(tmp_path, "p", {**CSV_MAPPING,
                                                                                            "tare": "auto"}))
    assert all(r.tare_counts == () for r in plain)  # resting near zero: left alone


def _skin():
    from tactile_descriptors_ros.core.robot import load_robot

    return load_robot("nao").cell_types["skin_cell"]


def _evaluate(capsys, source, mapping, *extra) -> tuple[int, dict | str]:
    rc = main(["evaluate", "--train", str(source), "--test", str(source), "--mapping", str(mapping),
               "--train-trials", "1", "--test-trials", "2", "--window", "1", "--windows", "contact",
               "--classifier", "pa", "--train-windows", "6", "--test-windows", "2",
               "--jobs", "1", "--cache", "", "--json", *extra])
    out = capsys.readouterr()
    return rc, (json.loads(out.out) if rc == 0 else out.err)


def test_evaluate_scores_skin_tables(trials, tmp_path, capsys):
    source, mapping = _write("hdf5", tmp_path, trials)
    rc, res = _evaluate(capsys, source, mapping)
    assert rc == 0, res
    assert res["class_names"] == ["cork", "steel"] and res["n_test"] == 4
    assert res["train_window_frames"] == 250  # 1 s of 250 Hz force frames
    assert res["n_features"] == len(selection_labels(_skin(), ("per_channel", "bands", "levels", "statistics")))
    assert res["in_contact_fraction"] == 1.0
    assert 0.5 <= res["classifiers"]["pa"]["accuracy"] <= 1.0


def test_evaluate_names_the_group_a_missing_skin_channel_leaves_out(trials, tmp_path, capsys):
    no_temp = {**HDF5_MAPPING, "channels": {k: v for k, v in SKIN_CHANNELS.items() if k != "temperature"}}
    source = write_skin_hdf5(tmp_path / "skin.h5", trials)
    mapping = _mapping(tmp_path, "notemp", no_temp)
    rc, err = _evaluate(capsys, source, mapping)
    assert rc == 2
    assert "feature group 'levels' needs channel 'temperature'" in err
    assert "per_channel, bands, statistics, levels:f1,f2,f3,proximity" in err
    rc, res = _evaluate(capsys, source, mapping, "--mode", "per_channel+levels:f1,f2,f3,proximity")
    assert rc == 0, res
    assert res["n_features"] == len(selection_labels(_skin(), ("per_channel",))) + 4


def test_skin_tables_are_not_imported_into_biotac_bags(trials, tmp_path, capsys):
    source, mapping = _write("csv", tmp_path, trials[:1])
    assert main(["import", str(source), "--mapping", str(mapping), "-o", str(tmp_path / "bag")]) == 2
    assert "tactile evaluate" in capsys.readouterr().err and not (tmp_path / "bag").exists()


def test_a_levels_channel_list_selects_those_levels_of_the_bank(trials, tmp_path):
    from tactile_descriptors_lab.evaluation.bank import compute_bank, mode_groups, select_features
    from tactile_descriptors_lab.evaluation.sampling import Window

    source, mapping = _write("npz", tmp_path, trials)
    recs = read_source(source, mapping)
    bank = compute_bank(recs, [Window(r.material, r.trial, 150, 250) for r in recs], cell_type=_skin())
    every, labels = select_features(bank, "levels", gate=False)
    assert labels == tuple(f"levels/level_{c}" for c in ("f1", "f2", "f3", "proximity", "temperature"))
    some, some_labels = select_features(bank, "levels:temperature,f2", gate=False)
    np.testing.assert_array_equal(some, every[:, [4, 1]])
    assert some_labels == ("levels:temperature,f2/level_temperature", "levels:temperature,f2/level_f2")
    np.testing.assert_allclose(some[:, 0], [t["temperature"][150:400].mean() for t in
                                            sorted(trials, key=lambda t: (t["class_name"], t["trial"]))])
    assert mode_groups("per_channel+levels:f1") == ("per_channel", "levels:f1")
    with pytest.raises(ConfigError, match=r"unknown descriptor mode 'per_channel\+level'"):
        mode_groups("per_channel+level")


def test_svm_on_too_few_training_trials_is_a_one_line_error(trials, tmp_path, capsys):
    source, mapping = _write("hdf5", tmp_path, trials)
    rc, err = _evaluate(capsys, source, mapping, "--classifier", "svm")
    assert rc == 2 and "Traceback" not in err
    assert "5-fold CV over trials (choosing the SVM's C) needs at least 5 training trials, there are 2" in err


def test_the_contact_threshold_is_the_recordings_robots(trials, tmp_path, capsys):
    """A robot file beside the mapping with F_t = 5 N: the 2 N touches hold no contact window."""
    from tactile_descriptors_ros.core.robot import robot_config_path

    robot = yaml.safe_load(robot_config_path("nao").read_text())
    robot["contact"] = {"force_threshold_n": 5.0, "release_threshold_n": 0.1}
    (tmp_path / "strict_nao.yaml").write_text(yaml.safe_dump(robot))
    source = write_skin_hdf5(tmp_path / "skin.h5", trials)
    mapping = _mapping(tmp_path, "strict", {**HDF5_MAPPING, "robot": "strict_nao.yaml"})
    rc, err = _evaluate(capsys, source, mapping)
    assert rc == 2 and "lies wholly in contact (force >= 5 N)" in err


def test_live_replay_of_skin_tables_is_refused_by_name(trials, tmp_path, capsys):
    source, mapping = _write("hdf5", tmp_path, trials)
    assert main(["evaluate", "--live", "--train", str(source), "--test", str(source), "--mapping", str(mapping)]) == 2
    assert "--live replays BioTac recordings through the window node; these hold cell type 'skin_cell'" in \
        capsys.readouterr().err
