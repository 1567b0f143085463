"""Other labs' layouts: the Penn BOLT HDF5 layout, numbered files, nested groups, composed trial numbers,
``.npy`` arrays of float values, the iCub's pressure-only taxel pads, a cell type's rates.

The layouts are built inside the tests from a few shared recordings (lab/test/datasets/writers.py), read
back through mapping files, and must give the recordings they were built from, sample for sample; bad
input must be one line naming the file, the key and what exists.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from writers import write_ros1_bag

from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
from tactile_descriptors_lab.datasets.layouts import (
    PENN_OBJECTS,
    icub_mapping,
    icub_robot_yaml,
    icub_taxel_counts,
    npy_split_mapping,
    penn_bolt_mapping,
    penn_run_name,
    write_icub_split,
    write_npy_split,
    write_penn_bolt,
)
from tactile_descriptors_lab.datasets.mapping import parse_mapping
from tactile_descriptors_lab.datasets.readers import LoadReport, read_source
from tactile_descriptors_lab.datasets.recording import CellRecording
from tactile_descriptors_lab.datasets.tables import group_glob, natural_key
from tactile_descriptors_ros.errors import ConfigError, DataFormatError
from tactile_descriptors_ros.tools.cli import main

RUNS_PER_SESSION = 2  # 2 sessions x 2 runs: trials 1-8 of each material, two fingers a run
FRAMES = 150

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def recs(biotac_data_dir, tmp_path_factory):
    """The first FRAMES rows of trials 1-8 of the Penn objects' materials, through the shipped mapping."""
    root = tmp_path_factory.mktemp("csv")
    for m in PENN_OBJECTS:
        (root / "raw_data" / f"mat{m}").mkdir(parents=True)
        for t in range(1, 4 * RUNS_PER_SESSION + 1):
            name = f"mat{m}/mat{m}_{t}_bio.csv"
            lines = (biotac_data_dir / "raw_data" / name).read_text().splitlines(keepends=True)
            (root / "raw_data" / name).write_text("".join(lines[:FRAMES + 1]))
    return load_recordings(root)


def _mapping(tmp: Path, d: dict, name: str = "penn") -> Path:
    p = tmp / f"{name}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _source_trial(session: int, run: int, finger: int) -> int:
    """The shared trial a run's finger was built from (writers.write_penn_bolt)."""
    return 2 * ((session - 1) * RUNS_PER_SESSION + run) - 1 + finger


def _same_samples(got, want) -> None:
    n = got.n_frames
    assert n == min(want.n_frames, FRAMES)
    assert np.array_equal(got.pac, want.pac[:n * want.pac_per_frame])
    assert np.array_equal(got.electrodes, want.electrodes[:, :n])
    for ch in ("pdc", "tac", "tdc"):
        assert np.array_equal(getattr(got, ch), getattr(want, ch)[:n]), ch


@pytest.mark.parametrize("finger", [0, 1])
def test_penn_bolt_channels_below_the_run_read_back_each_finger(recs, tmp_path, finger):
    written = write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION)
    got = read_source(tmp_path / "bolt.h5", _mapping(tmp_path, penn_bolt_mapping(finger)), tare="none")
    assert len(got) == len(written) == 4 * RUNS_PER_SESSION * len(PENN_OBJECTS) // 2
    by = {(r.material, r.trial): r for r in recs}
    number = {name: m for m, name in PENN_OBJECTS.items()}
    for r in got:
        session, run = divmod(r.trial, 100)
        assert r.path.endswith("#" + penn_run_name(r.class_name, session, run))
        src = by[(number[r.class_name], _source_trial(session, run, 0))]
        _same_samples(r, by[(number[r.class_name], _source_trial(session, run, finger))])
        # float seconds in the parent group of the fingers (finger_0's clock): to within a microsecond
        assert np.all(np.abs((r.frame_t_ns - r.frame_t_ns[0]) - (src.frame_t_ns[:r.n_frames] - src.frame_t_ns[0]))
                      < 1_000)
    assert sorted({r.trial for r in got}) == [101, 102, 201, 202]
    assert sorted({r.class_name for r in got}) == sorted(PENN_OBJECTS.values())


def test_a_finger_group_reads_the_runs_stamps_from_its_parent(recs, tmp_path):
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION)
    nested = penn_bolt_mapping(1)
    by_run = read_source(tmp_path / "bolt.h5", _mapping(tmp_path, nested), tare="none")
    per_finger = dict(nested, groups="*/biotacs/finger_1",
                      channels={k: k for k in ("pac", "pdc", "tac", "tdc", "electrodes")},
                      stamps={"column": "../timestamps", "unit": "s"},
                      **{"class": {"from": "group", "pattern": r"^(?P<class>.+)_\d+_\d+/"},
                         "trial": {"from": "group", "pattern": r"_(\d+)_(\d+)/", "number": "{0}{1:02d}"}})
    by_finger = read_source(tmp_path / "bolt.h5", _mapping(tmp_path, per_finger, "finger"), tare="none")
    assert [(r.class_name, r.trial) for r in by_finger] == [(r.class_name, r.trial) for r in by_run]
    for a, b in zip(by_finger, by_run):
        assert np.array_equal(a.frame_t_ns, b.frame_t_ns)
        assert np.array_equal(a.pac, b.pac) and np.array_equal(a.electrodes, b.electrodes)


def test_a_star_matches_one_group_level_and_two_stars_any():
    one, any_ = group_glob("*"), group_glob("**/finger_0")
    assert one.match("cork_1_01") and not one.match("cork_1_01/biotacs")
    assert any_.match("cork_1_01/biotacs/finger_0") and any_.match("finger_0")
    assert not any_.match("cork_1_01/biotacs/finger_1")
    assert group_glob("*/trial_[!0]?").match("cork/trial_12") and not group_glob("*/trial_[!0]?").match("cork/trial_01")
    assert group_glob("**").match("a/b/c")


def test_star_groups_leave_the_nested_sensor_groups_out(recs, tmp_path):
    """With ``groups: "*"`` only the runs are trials, not their ``biotacs`` and ``finger_<i>`` groups (each of
    which would be refused for lacking the channels, or read as a trial of its own)."""
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION)
    report = LoadReport(str(tmp_path), "")
    got = read_source(tmp_path / "bolt.h5", _mapping(tmp_path, penn_bolt_mapping(0)), report=report)
    assert len(got) == 4 * RUNS_PER_SESSION * len(PENN_OBJECTS) // 2
    assert all(r.path.count("/") == tmp_path.as_posix().count("/") + 1 for r in got)


def test_a_missing_run_leaves_a_gap_and_a_warning(recs, tmp_path, capsys):
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION, skip=(("cork", 1, 2),))
    report = LoadReport(str(tmp_path), "")
    got = read_source(tmp_path / "bolt.h5", _mapping(tmp_path, penn_bolt_mapping(0)), report=report, tare="none")
    assert sorted(r.trial for r in got if r.class_name == "cork") == [101, 201, 202]  # not renumbered 1-3
    assert report.note_lines() == ["classes hold different trials: cork lacks 102 (the other classes hold "
                                   "101-102,201-202): a split by trial number tests them on different runs"]
    assert main(["import", str(tmp_path / "bolt.h5"), "--mapping", str(tmp_path / "penn.yaml"),
                 "-o", str(tmp_path / "bag")]) == 0
    err = capsys.readouterr().err
    assert "warning: classes hold different trials: cork lacks 102" in err


def test_two_runs_with_one_trial_number_name_the_file_the_key_and_both_runs(recs, tmp_path):
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION)
    only_run = dict(penn_bolt_mapping(0), trial={"from": "group", "pattern": r"_(\d+)$"})
    mapping = _mapping(tmp_path, only_run)
    with pytest.raises(DataFormatError) as exc:
        read_source(tmp_path / "bolt.h5", mapping)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{mapping}: class bouncy_foam: trial 1 twice (")
    assert "bolt.h5#bouncy_foam_1_01 and " in msg and "bolt.h5#bouncy_foam_2_01" in msg
    assert "mapping key trial, from group, pattern '_(\\\\d+)$'" in msg


def test_a_group_glob_that_matches_nothing_names_the_file_the_key_and_the_groups(recs, tmp_path):
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION)
    mapping = _mapping(tmp_path, dict(penn_bolt_mapping(0), groups="*/finger_0"))
    with pytest.raises(DataFormatError) as exc:
        read_source(tmp_path / "bolt.h5", mapping)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{tmp_path / 'bolt.h5'}: no group matches '*/finger_0' (mapping key groups); groups: ")
    assert "bouncy_foam_1_01/biotacs/finger_0" in msg


def test_a_channel_path_the_run_lacks_names_the_paths_it_has(recs, tmp_path):
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION)
    m = penn_bolt_mapping(0)
    m["channels"] = dict(m["channels"], pac="biotacs/finger_2/pac")
    with pytest.raises(DataFormatError) as exc:
        read_source(tmp_path / "bolt.h5", _mapping(tmp_path, m))
    msg = str(exc.value)
    assert "no column 'biotacs/finger_2/pac' (mapping key channels.pac); the file has " in msg
    assert "biotacs/finger_0/pac" in msg


def test_trial_number_format_must_give_a_number(tmp_path):
    bad = dict(penn_bolt_mapping(0), trial={"from": "group", "pattern": r"_(\d+)_(\d+)$", "number": "s{0}"})
    with pytest.raises(ConfigError, match=re.escape("trial.number 's{0}' gives 's1' for 'bouncy_foam_1_01', not a number")):
        parse_mapping(bad).trial_rule.extract("bouncy_foam_1_01", "trial", "x")
    with pytest.raises(ConfigError, match="'trial.pattern': 'number' formats the groups of a pattern"):
        parse_mapping(dict(bad, trial={"from": "group", "number": "{0}"}))


def test_natural_order_numbers_bags_by_their_numbers(recs, tmp_path):
    """``<object>/<n>.bag`` with trials in order: ``10.bag`` is trial 10, not trial 2."""
    cork = [r for r in recs if r.material == 12]
    for n in range(1, 12):
        src = cork[(n - 1) % len(cork)]
        write_ros1_bag(tmp_path / "bags" / "cork" / f"{n}.bag", replace(
            src, frame_t_ns=src.frame_t_ns[:20], pac=src.pac[:20 * 22], pac_t_ns=src.pac_t_ns[:20 * 22],
            pdc=src.pdc[:20], tac=src.tac[:20], tdc=src.tdc[:20], electrodes=src.electrodes[:, :20]))
    got = read_source(tmp_path / "bags", tare="none")
    assert [r.trial for r in got] == list(range(1, 12))
    for r in got:  # each bag's PAC carries its file's number
        assert Path(r.source_file).name == f"{r.trial}.bag"
    assert sorted(["10.bag", "9.bag", "1.bag"], key=natural_key) == ["1.bag", "9.bag", "10.bag"]


def test_a_class_without_a_test_trial_is_one_line_naming_the_source_the_key_and_its_trials(recs, tmp_path, capsys):
    write_penn_bolt(tmp_path / "bolt.h5", recs, PENN_OBJECTS, RUNS_PER_SESSION, skip=(("cork", 1, 2),))
    mapping = _mapping(tmp_path, penn_bolt_mapping(0))
    source = str(tmp_path / "bolt.h5")
    code = main(["evaluate", "--train", source, "--test", source, "--mapping", str(mapping),
                 "--train-trials", "101,201,202", "--test-trials", "102", "--window", "0.5", "--classifier", "pa",
                 "--cache", ""])
    err = capsys.readouterr().err
    assert code != 0
    lines = [ln for ln in err.splitlines() if "has no test trial" in ln]
    assert lines == [f"tactile evaluate: error: {source}: '--test-trials': class cork has no test trial: "
                     "the test trials are 102, class cork holds trials 101,201-202"], err


# --------------------------------------------------------------------------- .npy arrays with a shape description

#: Stored units per count of the float arrays (a pad's normalised pressure): 1/64 keeps every count exact.
UNITS_PER_COUNT = 1 / 64


def _npy_splits(recs, tmp_path):
    train = [r for r in recs if r.trial <= 4]
    test = [r for r in recs if r.trial > 4]
    paths = [write_npy_split(tmp_path, "train", train, PENN_OBJECTS, FRAMES, UNITS_PER_COUNT),
             write_npy_split(tmp_path, "test", test, PENN_OBJECTS, FRAMES, UNITS_PER_COUNT)]
    return paths, train, test, _mapping(tmp_path, npy_split_mapping(1 / UNITS_PER_COUNT), "npy")


def test_npy_arrays_with_a_shape_description_and_float_values_read_back_the_counts(recs, tmp_path):
    (x_train, x_test), train, test, mapping = _npy_splits(recs, tmp_path)
    for path, want in ((x_train, train), (x_test, test)):
        got = read_source(path, mapping)
        assert len(got) == len(want)
        # trials in file order along the trial axis, classes by the labels file's names
        order = sorted(want, key=lambda r: (PENN_OBJECTS[r.material], r.trial))
        assert [r.class_name for r in got] == [PENN_OBJECTS[r.material] for r in order]
        for g, w in zip(got, order):
            _same_samples(g, w)
            assert np.all(np.diff(g.frame_t_ns) == 10_000_000)


def test_float_values_without_a_scale_and_a_wrong_shape_are_one_line_errors(recs, tmp_path):
    (x_train, _), _, _, mapping = _npy_splits(recs, tmp_path)
    d = yaml.safe_load(mapping.read_text())
    unscaled = _mapping(tmp_path, {k: v for k, v in d.items() if k != "counts_per_unit"}, "unscaled")
    with pytest.raises(DataFormatError) as exc:
        read_source(x_train, unscaled)
    assert "\n" not in str(exc.value)
    assert f"{x_train}: column 'pac1': not integer counts (non-integer values; give counts_per_unit" in str(exc.value)
    flat = {k: v for k, v in d.items() if k != "labels"}
    flat = _mapping(tmp_path, dict(flat, shape=["frame", "column"], trial="order",
                                   **{"class": {"from": "option", "value": "cork"}}), "flat")
    with pytest.raises(DataFormatError, match=re.escape(
            f"{x_train}: an array of shape ({len(recs) // 2}, 44, {FRAMES}), but the mapping's shape names 2 axes "
            "[frame, column] (mapping key shape")):
        read_source(x_train, flat)
    with pytest.raises(ConfigError, match="'shape': the axes of each array in order"):
        parse_mapping(dict(d, shape=["trial", "time", "column"]))


def test_evaluate_reads_npy_train_and_test_files(recs, tmp_path, capsys):
    (x_train, x_test), _, _, mapping = _npy_splits(recs, tmp_path)
    code = main(["evaluate", "--train", str(x_train), "--test", str(x_test), "--mapping", str(mapping),
                 "--window", "0.5", "--classifier", "pa", "--channels", "per_channel", "--cache", ""])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "pa: accuracy" in out.out and "bouncy_foam" in out.out


# --------------------------------------------------------------------------- groups a cell type cannot feed

PAD_ROBOT = """\
robot: {name: pad, description: a pressure pad read at 40 Hz}
cell_types:
  pad_cell:
    vibration: {symbol: p, rate_hz: 40.0, adc_bits: 12, axes: [{name: z, channels: [pz]}]}
    deformation: {symbol: F, rate_hz: 40.0, adc_bits: 12, axes: [{name: "", channels: [t1, t2, t3]}]}
    force: {channels: [t1, t2, t3], n_per_count: 0.01, rate_hz: 40.0}
body_parts:
  - {name: pad, cell_type: pad_cell, cells: [{id: 1}]}
"""


@pytest.fixture
def pad_source(recs, tmp_path):
    """A 40 Hz pad's tables from the shared recordings: its pressure is a trial's PDC, its three taxels
    the first three electrodes, frame after frame at the pad's rate."""
    (tmp_path / "pad.yaml").write_text(PAD_ROBOT)
    for r in recs:
        if r.trial > 6:
            continue
        d = tmp_path / "pad" / PENN_OBJECTS[r.material]
        d.mkdir(parents=True, exist_ok=True)
        lines = ["t_ns,pz,t1,t2,t3"] + [f"{i * 25_000_000},{r.pdc[i]},{r.electrodes[0, i]},{r.electrodes[1, i]},"
                                        f"{r.electrodes[2, i]}" for i in range(r.n_frames)]
        (d / f"trial_{r.trial}.csv").write_text("\n".join(lines) + "\n")
    mapping = _mapping(tmp_path, {"format": "csv", "files": "*/*.csv", "robot": "pad.yaml",
                                  "class": {"from": "folder"}, "trial": {"from": "file", "pattern": r"trial_(\d+)$"},
                                  "channels": {"pz": "pz", "t1": "t1", "t2": "t2", "t3": "t3"},
                                  "stamps": {"column": "t_ns", "unit": "ns"}, "tare": "none"}, "pad_map")
    return tmp_path / "pad", mapping


def _evaluate_pad(source, mapping, *mode):
    return main(["evaluate", "--train", str(source), "--test", str(source), "--mapping", str(mapping),
                 "--train-trials", "1-4", "--test-trials", "5-6", "--window", "1", "--classifier", "pa",
                 "--cache", "", *mode])


def test_a_group_the_cell_type_cannot_feed_is_left_out_of_the_default_with_a_note(pad_source, capsys):
    """At 40 Hz no vibration band lies below Nyquist: the default mode goes without ``bands`` and says so;
    a mode without bands evaluates (the bank no longer computes bands for every mode)."""
    assert _evaluate_pad(*pad_source) == 0
    out = capsys.readouterr()
    assert ("note: descriptor mode combined without bands (feature group 'bands' cannot be fed by cell type "
            "'pad_cell': its vibration rate (40 Hz) has no band") in out.err
    assert "descriptor mode per_channel+levels+statistics (" in out.out
    assert _evaluate_pad(*pad_source, "--mode", "per_channel") == 0
    assert "descriptor mode per_channel (" in capsys.readouterr().out


def test_a_group_asked_for_that_the_cell_type_cannot_feed_is_named_with_the_groups_that_work(pad_source, capsys):
    assert _evaluate_pad(*pad_source, "--mode", "combined") == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert len(err) == 1
    assert err[0].startswith("tactile evaluate: error: 'channels': mode 'combined': feature group 'bands' cannot "
                             "be fed by cell type 'pad_cell'")
    assert err[0].endswith("; the groups it can feed: paper, per_channel, levels, statistics, plain")


# --------------------------------------------------------------------------- a pressure-only cell type (iCub pads)

def _icub(recs, tmp_path):
    (tmp_path / "icub_pad.yaml").write_text(icub_robot_yaml())
    frames = FRAMES // 2
    x_train = write_icub_split(tmp_path, "train", [r for r in recs if r.trial <= 4], PENN_OBJECTS, frames)
    x_test = write_icub_split(tmp_path, "test", [r for r in recs if r.trial > 4], PENN_OBJECTS, frames)
    return x_train, x_test, _mapping(tmp_path, icub_mapping(), "icub")


def test_icub_pads_float_arrays_read_back_the_taxel_counts_of_a_pressure_only_cell(recs, tmp_path):
    x_train, _, mapping = _icub(recs, tmp_path)
    got = read_source(x_train, mapping)
    want = sorted([r for r in recs if r.trial <= 4], key=lambda r: (PENN_OBJECTS[r.material], r.trial))
    assert [g.class_name for g in got] == [PENN_OBJECTS[w.material] for w in want]
    for g, w in zip(got, want):
        assert isinstance(g, CellRecording) and g.cell_type == "taxel_pad"
        assert g.vibration.shape == (0, g.n_frames)  # pressure only: no vibration channel invented
        assert np.array_equal(g.deformation, icub_taxel_counts(w, FRAMES // 2).T)
        assert np.all(np.diff(g.frame_t_ns) == 20_000_000)


def test_icub_pads_evaluate_with_the_groups_pressure_can_feed(recs, tmp_path, capsys):
    x_train, x_test, mapping = _icub(recs, tmp_path)
    args = ["evaluate", "--train", str(x_train), "--test", str(x_test), "--mapping", str(mapping), "--window", "1",
            "--classifier", "pa", "--cache", ""]
    assert main(args) == 0
    out = capsys.readouterr()
    assert ("note: descriptor mode combined without per_channel, bands (feature group 'per_channel' reads the "
            "vibration channels, which cell type 'taxel_pad' does not have (pressure only))") in out.err
    assert "descriptor mode levels+statistics (" in out.out
    assert main(args + ["--mode", "per_channel"]) == 2
    err = capsys.readouterr().err
    assert err.strip().endswith("does not have (pressure only); the groups it can feed: paper, levels, statistics, plain")


def test_a_files_glob_that_matches_nothing_names_the_folder_the_key_and_what_it_holds(recs, tmp_path):
    (x_train, x_test), _, _, mapping = _npy_splits(recs, tmp_path)
    d = yaml.safe_load(mapping.read_text())
    wrong = _mapping(tmp_path, dict(d, files="data_*.npy"), "wrong")
    with pytest.raises(DataFormatError) as exc:
        read_source(tmp_path, wrong)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{tmp_path}: no files match 'data_*.npy' (mapping key files, {wrong}); the folder holds ")
    assert "X_test.npy, X_train.npy" in msg and "y_train.npy" in msg
