"""Every source ``tactile import`` and ``tactile evaluate`` read gives the recordings of the CSV path.

A few shared recordings are written, inside the test, as a Shadow ROS 1 bag,
a Shadow ROS 2 bag, a UPenn ROS 1 bag, an HDF5 table and NPZ tables; each is
read and imported, and must give the same samples and the same descriptors
as the CSV files they came from.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from writers import write_hdf5, write_npz, write_ros1_bag, write_ros2_shadow_bag

from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
from tactile_descriptors_lab.datasets.importer import ImportOptions, import_source
from tactile_descriptors_lab.datasets.mapping import load_mapping
from tactile_descriptors_lab.datasets.readers import LoadReport, read_source
from tactile_descriptors_ros.errors import ConfigError, DataFormatError
from tactile_descriptors_ros.tools.cli import main

MATERIALS, TRIALS, FRAMES = [2, 12], [1, 2], 300
#: Names another lab would give the two materials: they must reach the labels unchanged.
NAMES = {2: "bouncy_foam", 12: "cork"}

HDF5_MAPPING = {
    "format": "hdf5", "files": "*.h5", "groups": "*/trial_*",
    "class": {"from": "group", "pattern": "^([^/]+)/"}, "trial": {"from": "group", "pattern": r"trial_(\d+)$"},
    "samples_per_frame": 22,
    "channels": {"pac": "pac", "pdc": "pdc", "tac": "tac", "tdc": "tdc", "electrodes": "electrodes"},
    "stamps": {"column": "stamp_ns", "unit": "ns"},
}
NPZ_MAPPING = {
    "format": "npz", "files": "*/*.npz", "class": {"from": "folder"},
    "trial": {"from": "file", "pattern": r"_(\d+)$"},
    "channels": {"pac": "PAC", "pdc": "PDC", "tac": "TAC", "tdc": "TDC", "electrodes": "E"},
    "stamps": {"column": "t", "unit": "ns"},
}
BAG_MAPPING = {"format": "bag", "class": {"from": "folder"}, "trial": {"from": "file", "pattern": r"(\d+)$"}}


@pytest.fixture(scope="module")
def csv_recs(biotac_data_dir, tmp_path_factory):
    """The CSV path: the first FRAMES rows of a few shared recordings, read through the shipped mapping."""
    root = tmp_path_factory.mktemp("csv")
    for m in MATERIALS:
        (root / "raw_data" / f"mat{m}").mkdir(parents=True)
        for t in TRIALS:
            name = f"mat{m}/mat{m}_{t}_bio.csv"
            lines = (biotac_data_dir / "raw_data" / name).read_text().splitlines(keepends=True)
            (root / "raw_data" / name).write_text("".join(lines[:FRAMES + 1]))
    return load_recordings(root)


def _mapping(tmp: Path, name: str, d: dict) -> Path:
    p = tmp / f"{name}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _write(fmt: str, tmp: Path, recs) -> tuple[Path, Path]:
    """(source, mapping file) of ``recs`` written as ``fmt``."""
    if fmt == "hdf5":
        return write_hdf5(tmp / "trials.h5", recs, NAMES), _mapping(tmp, "h5", HDF5_MAPPING)
    if fmt == "npz":
        return write_npz(tmp / "npz", recs, NAMES), _mapping(tmp, "npz", NPZ_MAPPING)
    root = tmp / fmt
    for r in recs:
        target = root / NAMES[r.material] / f"trial_{r.trial}"
        if fmt == "shadow_ros1":
            write_ros1_bag(target.with_suffix(".bag"), r, "shadow", sensor=1)
        elif fmt == "upenn_ros1":
            write_ros1_bag(target.with_suffix(".bag"), r, "upenn", sensor=1)
        else:
            write_ros2_shadow_bag(target, r, sensor=1)
    return root, _mapping(tmp, fmt, {**BAG_MAPPING, "sensor": 1})


def _descriptor(rec) -> np.ndarray:
    from tactile_descriptors_ros.core.aggregation import CellSignals, describe_window
    from tactile_descriptors_ros.core.robot import load_robot

    robot = load_robot("shadow_hand")
    npc = robot.cell_types["biotac"].force.n_per_count
    cell = CellSignals(rec.pac[None], rec.pac_t_ns, rec.electrodes, rec.frame_t_ns, rec.pdc * npc)
    return describe_window(robot, {1: cell}).values


def _same(got, want, shifted: bool = False) -> None:
    assert [(r.class_name, r.trial) for r in got] == [(NAMES[r.material], r.trial) for r in want]
    for g, w in zip(got, want):
        for ch in ("pac", "pdc", "tac", "tdc", "electrodes"):
            np.testing.assert_array_equal(getattr(g, ch), getattr(w, ch), err_msg=ch)
        g0, w0 = (int(g.frame_t_ns[0]), int(w.frame_t_ns[0])) if shifted else (0, 0)
        np.testing.assert_array_equal(g.frame_t_ns - g0, w.frame_t_ns - w0)
        np.testing.assert_array_equal(g.pac_t_ns - g0, w.pac_t_ns - w0)
        np.testing.assert_array_equal(_descriptor(g), _descriptor(w))


@pytest.mark.realdata
@pytest.mark.parametrize("fmt", ["shadow_ros1", "shadow_ros2", "upenn_ros1", "hdf5", "npz"])
def test_each_format_reads_and_imports_to_the_csv_descriptors(fmt, csv_recs, tmp_path):
    source, mapping = _write(fmt, tmp_path, csv_recs)
    got = read_source(source, mapping)
    by_name = sorted(csv_recs, key=lambda r: (NAMES[r.material], r.trial))
    _same(sorted(got, key=lambda r: (r.class_name, r.trial)), by_name)
    # imported: the bag's trials read back give the same samples (moved in time) and descriptors
    bag = tmp_path / "imported"
    report = import_source(source, bag, mapping=mapping, options=ImportOptions(order="material"))
    assert [t.material_name for t in report.trials] == ["bouncy_foam"] * 2 + ["cork"] * 2
    back = read_source(bag)
    _same(sorted(back, key=lambda r: (r.class_name, r.trial)), by_name, shifted=True)


@pytest.mark.realdata
def test_import_command_prints_classes_from_the_data_and_the_contact_gate(csv_recs, tmp_path, capsys):
    source, mapping = _write("hdf5", tmp_path, csv_recs)
    assert main(["import", str(source), "--mapping", str(mapping), "-o", str(tmp_path / "bag")]) == 0
    out = capsys.readouterr().out
    assert "bouncy_foam" in out and "cork" in out and "cotton" not in out
    assert "contact gate" in out and "4 trials" in out


@pytest.mark.realdata
def test_untared_pressure_is_detected_and_tared_per_trial(csv_recs, tmp_path, capsys):
    """About 42 N at rest (840 counts at 0.05 N/count) would pass every frame through the contact gate."""
    offset = 840
    raised = [r.__class__(**{**r.__dict__, "pdc": r.pdc + offset, "electrodes": r.electrodes + 2000})
              for r in csv_recs]
    source, mapping = _write("hdf5", tmp_path, raised)
    report = LoadReport(str(source), "")
    tared = read_source(source, mapping, report=report)
    assert len(report.tared) == 4 and report.untared_detected
    assert "untared" in report.tare_lines()[0]
    raw = read_source(source, mapping, tare="none")
    assert all(np.all(r.force_n(0.05) >= 0.2) for r in raw)  # every frame "in contact"
    for t, r in zip(tared, raw):
        resting = r.pdc <= np.percentile(r.pdc, 5)  # the resting frames; each channel's median over them
        level = np.median(r.pdc[resting])
        assert level >= offset and t.tare_counts == (float(round(level)),)
        np.testing.assert_array_equal(t.pdc, np.clip(r.pdc - round(level), 0, None))
        e_level = np.round(np.median(r.electrodes[:, resting], axis=1))
        np.testing.assert_array_equal(t.electrodes, np.clip(r.electrodes - e_level[:, None], 0, None))
        assert t.pdc.min() == 0 and np.mean(t.force_n(0.05) >= 0.2) < 1.0
    # the import says so, and prints the gate statistics of the tared data
    assert main(["import", str(source), "--mapping", str(mapping), "-o", str(tmp_path / "bag")]) == 0
    out = capsys.readouterr().out
    assert "tared 4 trials" in out and "contact gate" in out


def test_mapping_typo_names_the_key(tmp_path):
    bad = dict(NPZ_MAPPING)
    bad["chanels"] = bad.pop("channels")
    with pytest.raises(ConfigError, match=r"'chanels'.*did you mean 'channels'"):
        load_mapping(_mapping(tmp_path, "typo", bad))
    nested = {**NPZ_MAPPING, "stamps": {"colum": "t"}}
    with pytest.raises(ConfigError, match=r"'stamps\.colum'.*did you mean 'column'"):
        load_mapping(_mapping(tmp_path, "typo2", nested))
    with pytest.raises(ConfigError, match="'tare'"):
        load_mapping(_mapping(tmp_path, "typo3", {**NPZ_MAPPING, "tare": "sometimes"}))


def _csv_copy(biotac_data_dir: Path, root: Path, drop: str | None = None) -> Path:
    d = root / "raw_data" / "mat2"
    d.mkdir(parents=True)
    lines = (biotac_data_dir / "raw_data" / "mat2" / "mat2_1_bio.csv").read_text().splitlines()[:101]
    if drop:
        header = lines[0].split(",")
        i = header.index(drop)
        lines = [",".join(x for j, x in enumerate(line.split(",")) if j != i) for line in lines]
    (d / "mat2_1_bio.csv").write_text("\n".join(lines) + "\n")
    return root


@pytest.mark.realdata
def test_missing_column_is_named(biotac_data_dir, tmp_path):
    root = _csv_copy(biotac_data_dir, tmp_path, drop="ele7")
    with pytest.raises(DataFormatError, match=r"missing column ele7 \(mapping key channels\.electrodes\)"):
        read_source(root)


def test_binary_and_undecodable_files_are_one_line_errors(tmp_path, capsys):
    bags = tmp_path / "bags" / "felt"
    bags.mkdir(parents=True)
    (bags / "trial_1.bag").write_bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    assert main(["import", str(tmp_path / "bags"), "-o", str(tmp_path / "bag")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "trial_1.bag: not a readable bag" in err
    d = tmp_path / "raw_data" / "mat1"
    d.mkdir(parents=True)
    rng = np.random.default_rng(0)
    (d / "mat1_1_bio.csv").write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    assert main(["import", str(tmp_path), "-o", str(tmp_path / "bag")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "mat1_1_bio.csv" in err and "Traceback" not in err
    (d / "mat1_1_bio.csv").write_bytes(b"timestamp,tdc\n\xff\xfe\xfa,1\n")
    with pytest.raises(DataFormatError, match="not a UTF-8 text file"):
        read_source(tmp_path)
    (tmp_path / "felt_1.npz").write_bytes(b"not a zip")
    with pytest.raises(DataFormatError, match="not an NPZ archive"):
        read_source(tmp_path / "felt_1.npz", _mapping(tmp_path, "n", NPZ_MAPPING))
    assert not (tmp_path / "bag").exists()


@pytest.mark.realdata
def test_failed_import_leaves_nothing_and_a_rerun_works(csv_recs, tmp_path):
    source, mapping = _write("npz", tmp_path, csv_recs)
    bag = tmp_path / "out" / "bag"

    def interrupted(recs):
        for i, r in enumerate(recs):
            if i == 2:
                raise KeyboardInterrupt  # Ctrl-C half-way through the bag
            yield r

    with pytest.raises(KeyboardInterrupt):
        import_source(source, bag, mapping=mapping, progress=interrupted)
    assert list((tmp_path / "out").iterdir()) == []
    report = import_source(source, bag, mapping=mapping)
    assert len(report.trials) == 4 and (bag / "metadata.yaml").is_file()
    listed = json.loads(yaml.safe_load((bag / "metadata.yaml").read_text())
                        ["rosbag2_bagfile_information"]["custom_data"]["tactile.trials"])
    assert [(e["class_name"], e["trial"], e["frames"]) for e in listed] == [
        ("bouncy_foam", 1, FRAMES), ("cork", 1, FRAMES), ("bouncy_foam", 2, FRAMES), ("cork", 2, FRAMES)]


@pytest.mark.realdata
def test_selections_larger_than_the_data_name_what_exists(biotac_data_dir):
    with pytest.raises(ConfigError, match=r"no trial 31-40; the data hold trials 1-30"):
        load_recordings(biotac_data_dir, trials=range(25, 41), materials=[3])
    with pytest.raises(ConfigError, match=r"no class 21; the data hold 1 carpet_net, 2 cotton, .*, 20 steel"):
        load_recordings(biotac_data_dir, trials=[1], materials=[20, 21])
    with pytest.raises(ConfigError, match=r"no class 25; the data hold 1 carpet_net, .*, 20 steel"):
        load_recordings(biotac_data_dir, materials=[25])
    with pytest.raises(ConfigError, match=r"no trial 40; the data hold trials 1-30"):
        load_recordings(biotac_data_dir, trials=[40], materials=[2])


@pytest.mark.realdata
def test_whole_second_stamps_need_a_frame_rate_and_work_with_one(csv_recs, tmp_path):
    recs = csv_recs[:1]
    d = tmp_path / "npz" / "felt"
    d.mkdir(parents=True)
    r = recs[0]
    whole_s = (r.frame_t_ns // 1_000_000_000).astype(np.int64)
    np.savez(d / "felt_1.npz", t=whole_s, PAC=r.pac.reshape(-1, 22), E=r.electrodes.T, PDC=r.pdc, TAC=r.tac,
             TDC=r.tdc)
    plain = {**NPZ_MAPPING, "stamps": {"column": "t", "unit": "s"}}
    with pytest.raises(DataFormatError, match="rate_hz"):
        read_source(tmp_path / "npz", _mapping(tmp_path, "s", plain))
    rated = {**NPZ_MAPPING, "stamps": {"column": "t", "unit": "s", "rate_hz": 100}}
    (got,) = read_source(tmp_path / "npz", _mapping(tmp_path, "r", rated))
    assert got.class_name == "felt" and got.frame_t_ns[0] == whole_s[0] * 1_000_000_000
    assert np.all(np.diff(got.frame_t_ns) == 10_000_000)
    np.testing.assert_array_equal(got.pac, r.pac)


def test_contact_windows_lie_wholly_in_contact():
    from tactile_descriptors_lab.datasets.recording import BiotacRecording
    from tactile_descriptors_lab.evaluation.sampling import draw_contact_windows

    n = 400
    t = np.arange(n, dtype=np.int64) * 10_000_000
    pdc = np.zeros(n, dtype=np.int64)
    pdc[100:300] = 100  # 5 N from frame 100 to 299
    rec = BiotacRecording(material=1, trial=1, frame_t_ns=t, pac=np.zeros(n * 22, np.int64),
                          pac_t_ns=np.arange(n * 22, dtype=np.int64) * 454_545, pdc=pdc, tac=pdc, tdc=pdc,
                          electrodes=np.zeros((19, n), np.int64), path="synthetic")
    never = BiotacRecording(**{**rec.__dict__, "trial": 2, "pdc": np.zeros(n, np.int64)})
    wins, without = draw_contact_windows([rec, never], 50, 8, 0, 0.05, 0.2)
    assert len(wins) == 8 and without == [never]
    assert all(100 <= w.start and w.start + w.n_frames <= 300 for w in wins)
    assert len({w.start for w in wins}) == 8  # no position twice
    assert wins == draw_contact_windows([rec], 50, 8, 0, 0.05, 0.2)[0]  # seeded


@pytest.mark.realdata
def test_evaluate_scores_an_hdf5_table_and_its_imported_bag_alike(csv_recs, tmp_path, capsys):
    source, mapping = _write("hdf5", tmp_path, csv_recs)
    bag = tmp_path / "bag"
    assert main(["import", str(source), "--mapping", str(mapping), "-o", str(bag)]) == 0
    capsys.readouterr()
    common = ["--train-trials", "1", "--test-trials", "2", "--window", "0.5", "--windows", "contact",
              "--channels", "per_channel", "--classifier", "pa", "--train-windows", "3", "--test-windows", "2",
              "--jobs", "1", "--cache", "", "--json"]
    results = []
    for args in (["--train", str(source), "--test", str(source), "--mapping", str(mapping)],
                 ["--train", str(bag), "--test", str(bag)]):
        assert main(["evaluate", *args, *common]) == 0
        results.append(json.loads(capsys.readouterr().out))
    a, b = results
    assert a["class_names"] == b["class_names"] == ["bouncy_foam", "cork"]
    assert a["n_train"] == b["n_train"] and a["n_test"] == b["n_test"] == 4
    assert a["classifiers"]["pa"]["confusion"] == b["classifiers"]["pa"]["confusion"]
    # ranges larger than the data are refused, naming what exists
    assert main(["evaluate", "--train", str(bag), "--test", str(bag), "--train-trials", "1-5", *common[2:]]) == 2
    assert "no trial 3-5; the data hold trials 1-2" in capsys.readouterr().err


def test_evaluate_refuses_pac_at_another_rate_for_the_groups_that_read_it():
    from tactile_descriptors_lab.datasets.recording import BiotacRecording
    from tactile_descriptors_lab.verbs.cmd_evaluate import check_pac_rate, check_recordings

    n = 100
    t = np.arange(n, dtype=np.int64) * 10_000_000
    two = BiotacRecording(material=1, trial=1, frame_t_ns=t, pac=np.zeros(2 * n, np.int64),
                          pac_t_ns=np.arange(2 * n, dtype=np.int64) * 5_000_000, pdc=np.zeros(n, np.int64),
                          tac=np.zeros(n, np.int64), tdc=np.zeros(n, np.int64),
                          electrodes=np.zeros((19, n), np.int64), path="old_shadow.bag", pac_per_frame=2)
    with pytest.raises(ConfigError, match=r"old_shadow.bag \(mode paper\): feature group 'paper' needs channel "
                                          r"'pac'.*pac at 200 Hz \(2 samples a frame.*can feed: levels$"):
        check_pac_rate([two])
    check_recordings([two], "levels")  # electrodes, PDC, TDC, TAC: no PAC read
    full = BiotacRecording(**{**two.__dict__, "pac": np.zeros(22 * n, np.int64), "pac_per_frame": 22,
                              "pac_t_ns": np.arange(22 * n, dtype=np.int64) * 454_545})
    check_pac_rate([full])


def test_the_readers_import_no_ros_client_library():
    """datasets/ reads bags with rosbags alone: rclpy and the generated messages are blocked."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(
        """
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in ('rclpy', 'rosidl_runtime_py', 'tactile_descriptors_msgs', 'std_msgs',
                                          'builtin_interfaces'):
                    raise ImportError('blocked for this test: ' + name)
        sys.meta_path.insert(0, Block())
        from tactile_descriptors_lab.datasets import bagfiles, mapping, msgdefs, readers, recording, tables
        from tactile_descriptors_ros.bags.types import tactile_typestore
        store = msgdefs.foreign_typestore()
        assert msgdefs.SHADOW_ALL in store.types and msgdefs.UPENN_HAND in store.types
        assert 'tactile_descriptors_msgs/msg/BioTacFrameBatch' in tactile_typestore().types
        print('ok')
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


@pytest.mark.realdata
def test_old_shadow_bags_evaluate_with_the_groups_their_channels_feed(csv_recs, tmp_path, capsys):
    """``pac0, pac1`` a message is no 2.2 kHz PAC: groups reading PAC are refused, naming what works."""
    from writers import write_old_shadow_bag

    mapping = _mapping(tmp_path, "bag", BAG_MAPPING)
    common = ["--mapping", str(mapping), "--train-trials", "1", "--test-trials", "2", "--window", "0.5",
              "--classifier", "pa", "--train-windows", "4", "--test-windows", "2", "--jobs", "1", "--cache", "",
              "--json"]
    for electrodes in (True, False):
        root = tmp_path / ("old" if electrodes else "old_no_electrodes")
        for r in csv_recs:
            write_old_shadow_bag(root / NAMES[r.material] / f"trial_{r.trial}.bag", r, electrodes=electrodes)
        got = read_source(root, mapping)
        assert [g.pac_per_frame for g in got] == [2] * 4
        np.testing.assert_array_equal(got[0].pac.reshape(-1, 2), csv_recs[0].pac.reshape(-1, 22)[:, :2])
        assert got[0].absent == (() if electrodes else tuple(f"e{i}" for i in range(1, 20)))
        run = ["evaluate", "--train", str(root), "--test", str(root), *common]
        assert main(run) == 2  # the default descriptor reads PAC
        err = capsys.readouterr().err
        assert "feature group 'per_channel' needs channel 'pac'" in err
        assert "pac at 200 Hz (2 samples a frame at 100.0 frames/s), not the 2200 Hz" in err
        able = "levels" if electrodes else "levels:pdc,tdc,tac"
        assert err.rstrip().endswith(f"the groups they can feed: {able}")
        if not electrodes:
            assert main([*run, "--mode", "levels"]) == 2
            assert "feature group 'levels' needs channel 'e1' (and 18 more)" in capsys.readouterr().err
        assert main([*run, "--mode", able]) == 0
        res = json.loads(capsys.readouterr().out)
        assert res["n_features"] == (22 if electrodes else 3) and res["class_names"] == ["bouncy_foam", "cork"]
