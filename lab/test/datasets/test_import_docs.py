"""lab/docs/import.md: its mapping files parse and read their formats, and every command on the page runs."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from writers import write_hdf5, write_npz, write_old_shadow_bag, write_ros1_bag, write_ros2_shadow_bag

from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
from tactile_descriptors_lab.datasets.layouts import (
    simulated_skin_trials,
    write_npy_split,
    write_penn_bolt,
    write_skin_hdf5,
)
from tactile_descriptors_lab.datasets.mapping import load_mapping
from tactile_descriptors_lab.datasets.readers import read_source
from tactile_descriptors_ros.tools.cli import main

NAMES = {2: "bouncy_foam", 12: "cork"}
FRAMES = 250


def _page(repo_dir: Path) -> tuple[dict[str, str], list[str]]:
    """The page's YAML blocks by the file name introducing them, and its ``tactile`` command lines."""
    text = (repo_dir / "lab" / "docs" / "import.md").read_text()
    files, commands = {}, []
    for m in re.finditer(r"```(\w+)\n(.*?)```", text, re.S):
        lang, body = m.group(1), m.group(2)
        if lang == "yaml":
            before = text[:m.start()].rstrip().rsplit("\n\n", 1)[-1]
            name = re.search(r"`([\w.]+\.yaml)`", before)
            assert name, f"a YAML block without a file name before it: {before!r}"
            files[name.group(1)] = body
        elif lang == "sh":
            commands += [line for line in body.splitlines() if line.startswith("tactile ")]
    return files, commands


@pytest.fixture(scope="module")
def recs(biotac_data_dir):
    out = load_recordings(biotac_data_dir, trials=[1, 2], materials=[2, 12])
    return [r.crop_frames(0, FRAMES) for r in out]


@pytest.mark.realdata
def test_every_command_of_the_page_runs(repo_dir, biotac_data_dir, recs, tmp_path, monkeypatch, capsys):
    files, commands = _page(repo_dir)
    assert {"shadow.yaml", "hdf5.yaml", "npz.yaml", "labels.yaml", "skin.yaml", "penn.yaml", "arrays.yaml"} <= set(files)
    assert len(commands) >= 10
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "shared").symlink_to(biotac_data_dir.parents[1])  # ../shared as seen from work/
    for name, body in files.items():
        (work / name).write_text(body)
        load_mapping(work / name)  # every mapping of the page parses
    for r in recs:
        stem = f"{NAMES[r.material]}/trial_{r.trial}"
        write_ros1_bag(work / "shadow_ros1" / f"{stem}.bag", r, "shadow", sensor=1)
        write_ros2_shadow_bag(work / "shadow_ros2" / stem, r, sensor=1)
        write_ros1_bag(work / "upenn_ros1" / f"{stem}.bag", r, "upenn", sensor=0)
        write_old_shadow_bag(work / "shadow_old" / f"{stem}.bag", r, sensor=1)
    write_hdf5(work / "recordings.h5", recs, NAMES)
    write_npz(work / "npz", recs, NAMES)
    write_skin_hdf5(work / "skin.h5", simulated_skin_trials())
    write_penn_bolt(work / "penn.h5", recs, NAMES, runs_per_session=1)
    for split, trial in (("train", 1), ("test", 2)):
        write_npy_split(work, split, [r for r in recs if r.trial == trial], NAMES, FRAMES, 1 / 64)
    monkeypatch.chdir(work)
    for line in commands:
        rc = main(shlex.split(line)[1:])
        out = capsys.readouterr()
        assert rc == 0, f"{line}\n{out.err}"
        assert "contact gate" in out.out or "evaluate" in line, line


@pytest.mark.realdata
def test_the_label_column_mapping_reads_trials_from_runs_of_one_file(repo_dir, recs, tmp_path):
    files, _ = _page(repo_dir)
    mapping = tmp_path / "labels.yaml"
    mapping.write_text(files["labels.yaml"])
    header = ["time", "object", "trial", *(f"pac{i}" for i in range(1, 23)), "pdc", "tac", "tdc",
              *(f"e{i}" for i in range(1, 20))]
    lines = [",".join(header)]
    for r in recs:
        pac = r.pac.reshape(r.n_frames, 22)
        for i in range(r.n_frames):
            row = [str(int(r.frame_t_ns[i] // 1_000_000_000)), NAMES[r.material], str(r.trial),
                   *map(str, pac[i]), str(r.pdc[i]), str(r.tac[i]), str(r.tdc[i]), *map(str, r.electrodes[:, i])]
            lines.append(",".join(row))
    (tmp_path / "all.csv").write_text("\n".join(lines) + "\n")
    got = read_source(tmp_path / "all.csv", mapping)
    assert [(g.class_name, g.trial, g.n_frames) for g in got] == [
        ("bouncy_foam", 1, FRAMES), ("bouncy_foam", 2, FRAMES), ("cork", 1, FRAMES), ("cork", 2, FRAMES)]
    want = sorted(recs, key=lambda r: (NAMES[r.material], r.trial))
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g.pac, w.pac)
        np.testing.assert_array_equal(g.electrodes, w.electrodes)
        assert np.all(np.diff(g.frame_t_ns) == 10_000_000)
