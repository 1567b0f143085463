"""``tactile import``: 2 materials x 2 real trials into a bag, checked against the CSV files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_descriptors_lab.datasets.biotac_slide import read_biotac_csv
from tactile_descriptors_lab.datasets.importer import ImportOptions, import_biotac_slide, parse_index_ranges
from tactile_descriptors_ros.bags.io import BagReader
from tactile_descriptors_ros.errors import ConfigError, DataFormatError
from tactile_descriptors_ros.tools.cli import main


def _stamp(h) -> int:
    return h.stamp.sec * 1_000_000_000 + h.stamp.nanosec


@pytest.mark.realdata
def test_import_two_materials_two_trials(tmp_path, biotac_data_dir):
    bag = tmp_path / "bag"
    report = import_biotac_slide(biotac_data_dir, bag, trials=[1, 2], materials=[2, 12], storage="sqlite3")
    recs = {(m, t): read_biotac_csv(biotac_data_dir / "raw_data" / f"mat{m}" / f"mat{m}_{t}_bio.csv")
            for m in (2, 12) for t in (1, 2)}
    order = [(2, 1), (12, 1), (2, 2), (12, 2)]  # interleaved by trial
    assert [(t.material, t.trial) for t in report.trials] == order
    assert report.frames == sum(r.n_frames for r in recs.values())
    # contact gate: force = PDC * 0.05 N/count >= 0.2 N, straight from the CSV
    in_contact = sum(int(np.count_nonzero(r.pdc * 0.05 >= 0.2)) for r in recs.values())
    assert report.frames_in_contact == in_contact
    assert report.contact_fraction == pytest.approx(in_contact / report.frames)

    with BagReader(bag) as reader:
        info = reader.info
        assert set(info.topics) == {"/tactile/index/frames", "/tactile/label"}
        msgs = [(m, reader.deserialize(m)) for m in reader.messages()]
    labels = [d for m, d in msgs if m.topic == "/tactile/label"]
    assert [d.class_name for d in labels] == [recs[k].class_name for k in order] == ["cotton", "cork"] * 2
    batches = [(m, d) for m, d in msgs if m.topic == "/tactile/index/frames"]
    assert len(batches) == report.batches
    seqs = [d.first_frame_sequence for _, d in batches]
    counts = [d.frame_count for _, d in batches]
    assert seqs == list(np.concatenate([[0], np.cumsum(counts)[:-1]]))  # no lost frames
    # the first trial: stamps, PAC and electrodes exactly as in the CSV
    rec = recs[(2, 1)]
    first_trial = batches[: -(-rec.n_frames // 10)]
    pac = np.concatenate([d.pac for _, d in first_trial]).astype(np.int64)
    assert np.array_equal(pac, rec.pac)
    pac_t = np.concatenate([_stamp(d.header) + d.pac_offset_ns for _, d in first_trial])
    assert np.array_equal(pac_t, rec.pac_t_ns)
    el = np.concatenate([d.electrodes.reshape(d.frame_count, 19) for _, d in first_trial]).T
    assert np.array_equal(el, rec.electrodes)
    d0 = first_trial[0][1]
    assert _stamp(d0.header) == rec.frame_t_ns[0] and d0.body_part == "index" and d0.sensor_name == "biotac_index"
    assert d0.chip_select == 0 and d0.serial_number == "" and d0.pdc_tare_counts == 0.0
    assert d0.force_n_per_count == 0.05 and d0.pac_pa_per_count == 0.37 and len(d0.electrode_tare_counts) == 0
    # each label comes inside the release gap, after its trial's last recorded frame
    for stats, label_msg in zip(report.trials, [m for m, _ in msgs if m.topic == "/tactile/label"]):
        assert stats.end_ns < label_msg.log_time_ns < stats.end_ns + 1_000_000_000
    # trial k+1 starts about release_s after trial k ended; release frames carry zero force
    for a, b in zip(report.trials, report.trials[1:]):
        assert 0.98e9 <= b.start_ns - a.end_ns <= 1.0e9
    release = [d for m, d in batches if a.end_ns <= _stamp(d.header) < b.start_ns]
    assert release and all(not d.pdc.any() and not d.pac.any() for d in release)


@pytest.mark.realdata
def test_import_command_json(tmp_path, biotac_data_dir, capsys):
    out = tmp_path / "bag"
    assert main(["import", str(biotac_data_dir), "-o", str(out), "--trials", "3", "--materials", "1,20",
                 "--no-release-fill", "--max-frames", "300", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["trials"] == 2 and d["frames"] == 600 and d["release_frames"] == 0 and d["labels"] == 2
    assert d["batches"] == 60 and 0.0 <= d["contact_fraction"] <= 1.0


def test_options_and_ranges_are_checked(tmp_path):
    assert parse_index_ranges("1-3,7") == [1, 2, 3, 7]
    for bad in ("3-1", "x", "", "0"):
        with pytest.raises(ConfigError):
            parse_index_ranges(bad)
    with pytest.raises(ConfigError, match="label_delay_s"):
        ImportOptions(label_delay_s=2.0, release_s=1.0).validate()
    with pytest.raises(DataFormatError):
        import_biotac_slide(tmp_path, tmp_path / "bag")  # no recordings: a clear error, no bag
    assert not (tmp_path / "bag").exists()


def test_unknown_body_part_fails(tmp_path):
    (tmp_path / "raw_data" / "mat1").mkdir(parents=True)
    (tmp_path / "raw_data" / "mat1" / "mat1_1_bio.csv").write_text("x\n")
    with pytest.raises(ConfigError, match="unknown body part"):
        import_biotac_slide(tmp_path, tmp_path / "bag", options=ImportOptions(body_part="tail"))
