"""The model on disk (core.model_store): journal, compaction, full disk, damage, lock, temp files."""

from __future__ import annotations

import errno
import json
import os

import numpy as np
import pytest

from tactile_descriptors_ros.core.learning import OnlineClassifier
from tactile_descriptors_ros.core.model_store import ModelStore, journal_path, load_model, save_model
from tactile_descriptors_ros.errors import ModelError

# ------------------------------------------------------------ journal


def _learn_some(clf: OnlineClassifier, store, n: int, rng, classes: int = 5, offset: int = 0) -> None:
    for i in range(n):
        v = rng.uniform(0.5, 3.0, len(clf.labels))
        clf.observe(v)
        clf.learn(v, f"c{(i + offset) % classes}")
        store.record(clf)


def test_journal_replays_to_the_same_bits_and_survives_a_torn_last_line(tmp_path):
    path = tmp_path / "model.json"
    clf = OnlineClassifier(["A_x", "M_x", "C_x"], update="max_loss", average=True)
    store = ModelStore(path)
    _learn_some(clf, store, 30, np.random.default_rng(1), classes=7)
    assert journal_path(path).exists() and store.compactions == 0
    back = load_model(path)
    assert json.dumps(back.state()) == json.dumps(clf.state())          # bit-identical, counters included
    # a crash in the middle of an append: the last, unreported entry is absent, never half applied
    with open(journal_path(path), "ab") as fh:
        fh.write(b'{"version": 31, "new_classes": [')
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())
    # a store opened on it compacts: one file, the same model, and learning goes on
    store.close()
    store2 = ModelStore(path)
    again = store2.open()
    assert not journal_path(path).exists() and json.dumps(again.state()) == json.dumps(clf.state())
    _learn_some(again, store2, 3, np.random.default_rng(2))
    assert load_model(path).version == 33


def test_journal_entry_size_does_not_grow_with_the_classes(tmp_path):
    """Saving one label writes the changed rows only: its bytes are the same for 10 and 1,000 classes."""
    sizes = {}
    for n_classes in (10, 1000):
        path = tmp_path / f"m{n_classes}.json"
        clf = OnlineClassifier([f"A_{i}" for i in range(8)])
        for c in range(n_classes):
            clf.pa.add_class(f"class_{c}")
        store = ModelStore(path)
        store.save(clf)
        _learn_some(clf, store, 1, np.random.default_rng(3))
        before = store.journal_bytes
        _learn_some(clf, store, 1, np.random.default_rng(4), offset=1)
        sizes[n_classes] = store.journal_bytes - before
    assert (tmp_path / "m1000.json").stat().st_size > 50 * sizes[1000]  # a whole rewrite would be 50x more
    assert abs(sizes[1000] - sizes[10]) < 0.1 * sizes[10]


def test_journal_entries_are_written_over_reserved_zeros(tmp_path):
    """The journal file is extended ahead of its entries, so syncing an entry changes neither its size nor its
    blocks (no filesystem metadata to commit); a torn entry over the zeros is ignored; a journal written
    without a reserve (plain appends) loads the same."""
    path = tmp_path / "model.json"
    clf = OnlineClassifier([f"A_{i}" for i in range(8)])
    store = ModelStore(path, reserve_bytes=64 << 10)
    store.save(clf)
    _learn_some(clf, store, 1, np.random.default_rng(0))
    size = journal_path(path).stat().st_size
    assert size >= 64 << 10 and size % 4096 == 0 and store.extensions == 1
    assert store.journal_bytes < size
    _learn_some(clf, store, 10, np.random.default_rng(1))
    assert journal_path(path).stat().st_size == size and store.extensions == 1  # written over the zeros
    raw = journal_path(path).read_bytes()
    assert raw[store.journal_bytes:] == bytes(size - store.journal_bytes)
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())
    # past the reserve the file is extended once more, by at least the reserve
    rng = np.random.default_rng(2)
    for _ in range(1000):
        if journal_path(path).stat().st_size != size:
            break
        _learn_some(clf, store, 1, rng)
    assert store.extensions == 2 and journal_path(path).stat().st_size >= size + (64 << 10)
    assert store.compactions == 0
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())
    # a crash while writing an entry over the zeros: its beginning, no newline, zeros after it
    with open(journal_path(path), "r+b") as fh:
        fh.seek(store.journal_bytes)
        fh.write(b'{"version": 99, "new_classes": [')
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())
    store.close()
    # the same labels appended without a reserve: the file is exactly the entries, and loads the same
    plain = tmp_path / "plain.json"
    clf2 = OnlineClassifier([f"A_{i}" for i in range(8)])
    store2 = ModelStore(plain, reserve_bytes=0)
    store2.save(clf2)
    _learn_some(clf2, store2, 5, np.random.default_rng(0))
    assert journal_path(plain).stat().st_size == store2.journal_bytes and store2.extensions == 0
    assert json.dumps(load_model(plain).state()) == json.dumps(clf2.state())


def test_stale_or_corrupt_journal(tmp_path):
    path = tmp_path / "model.json"
    clf = OnlineClassifier(["A_x", "M_x"])
    store = ModelStore(path)
    _learn_some(clf, store, 4, np.random.default_rng(0))
    journal = journal_path(path).read_bytes()
    store.close()
    # a rewrite of the file (e.g. a reset) followed by a crash before the journal was dropped: stale, skipped
    fresh = OnlineClassifier(["A_x", "M_x"])
    save_model(fresh, path)
    journal_path(path).write_bytes(journal)
    assert load_model(path).version == 0
    # a corrupt entry in the middle is an error naming the journal and its line
    _learn_some(fresh, ModelStore(path), 3, np.random.default_rng(0))
    lines = journal_path(path).read_bytes().split(b"\n")
    entry = json.loads(lines[2])
    entry["weights"][0][0] = float("nan")
    lines[2] = json.dumps(entry).encode()
    journal_path(path).write_bytes(b"\n".join(lines))
    with pytest.raises(ModelError, match=r"model.json.journal: line 3: 'weights' holds 1 non-finite"):
        load_model(path)


def test_journal_compacts_once_it_outgrows_the_file(tmp_path):
    path = tmp_path / "model.json"
    clf = OnlineClassifier(["A_x", "M_x"])
    store = ModelStore(path, min_compact_bytes=0)
    _learn_some(clf, store, 40, np.random.default_rng(0))
    assert store.compactions >= 1
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())
    assert store.journal_bytes <= path.stat().st_size + 2_000


# ------------------------------------------------------------ full disk


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_at_compaction_keeps_the_journal_and_every_acknowledged_label(tmp_path, monkeypatch):
    """Compaction fails on ENOSPC: the journal stays open and appendable, every later label is durable,
    and after a kill (no clean close) and the disk freed, a new store loads every acknowledged label."""
    from tactile_descriptors_ros.core import model_store

    path = tmp_path / "model.json"
    clf = OnlineClassifier([f"A_{i}" for i in range(4)], update="max_loss", average=True)
    store = ModelStore(path, holder="first", min_compact_bytes=0)
    _learn_some(clf, store, 3, np.random.default_rng(0))
    assert store.compactions >= 1
    snapshot = path.read_bytes()
    monkeypatch.setattr(model_store, "_write_all", _enospc)  # every rewrite of the model file fails from here
    acknowledged = 0
    for k in range(40):
        _learn_some(clf, store, 1, np.random.default_rng(10 + k), offset=k)  # record() returns: durable
        acknowledged = clf.version
    assert store.compaction_failures >= 2 and "No space left" in store.compaction_error
    assert path.read_bytes() == snapshot and not list(tmp_path.glob(".*.tmp"))
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())  # the journal holds them all
    store.close()  # as a kill leaves it: no compaction at the end
    # a restart while the disk is still full: it loads, cannot compact, and appends where the entries end
    second = ModelStore(path, holder="second", min_compact_bytes=0)
    again = second.open()
    assert again.version == acknowledged and second.compaction_failures == 1
    _learn_some(again, second, 5, np.random.default_rng(99))
    second.close()
    monkeypatch.undo()  # the disk is freed
    third = ModelStore(path, holder="third")
    final = third.open()
    assert json.dumps(final.state()) == json.dumps(again.state()) and final.version == acknowledged + 5
    assert not journal_path(path).exists() and third.compactions == 1  # compacted at start
    third.close()


def test_a_failed_journal_append_is_not_saved_and_the_next_label_saves_both(tmp_path, monkeypatch):
    from tactile_descriptors_ros.core import model_store

    path = tmp_path / "model.json"
    clf = OnlineClassifier(["A_x", "M_x"])
    store = ModelStore(path, reserve_bytes=0)
    _learn_some(clf, store, 3, np.random.default_rng(0))
    monkeypatch.setattr(model_store.os, "pwrite", _enospc)
    with pytest.raises(ModelError, match="No space left"):
        _learn_some(clf, store, 1, np.random.default_rng(1), offset=3)
    monkeypatch.undo()
    assert load_model(path).version == 3  # the failed label is not on disk, and nothing else was lost
    _learn_some(clf, store, 1, np.random.default_rng(2), offset=4)  # two updates since the last record: rewrite
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state()) and clf.version == 5


# ------------------------------------------------------------ damage


def _journalled(tmp_path, n: int = 10):
    path = tmp_path / "model.json"
    clf = OnlineClassifier(["A_x", "M_x", "C_x"])
    store = ModelStore(path)
    store.save(clf)
    _learn_some(clf, store, n, np.random.default_rng(5))
    store.close()
    return path, clf


@pytest.mark.parametrize("damage", ["zeroed", "garbled"])
def test_damage_in_the_middle_of_a_journal_is_refused_naming_the_line_and_recovered(tmp_path, damage, capsys):
    from tactile_descriptors_ros.core.model_store import recover_model
    from tactile_descriptors_ros.tools.cli import main

    path, clf = _journalled(tmp_path)
    journal = journal_path(path)
    data = bytearray(journal.read_bytes())
    lines = bytes(data).split(b"\n")
    start = sum(len(x) + 1 for x in lines[:5])  # line 6 (the header is line 1): entry 5
    end = start + len(lines[5])
    data[start:end] = bytes(end - start) if damage == "zeroed" else b"#" * (end - start)
    journal.write_bytes(bytes(data))
    with pytest.raises(ModelError, match=r"model.json.journal: line 6: .*tactile model recover .*model.json"):
        load_model(path)
    assert main(["model", "check", str(path)]) == 1
    assert "line 6" in capsys.readouterr().out
    assert main(["model", "recover", str(path)]) == 0
    out = capsys.readouterr().out
    assert "kept 4 entries" in out and "line 6" in out
    recovered = load_model(path)
    assert recovered.version == 4  # the entries before the damage, none after it
    assert (tmp_path / "model.json.journal.damaged").read_bytes() == bytes(data)  # set aside, not deleted
    assert recover_model(path).damaged_line is None  # now clean


def test_an_entry_torn_by_a_crash_is_not_damage(tmp_path):
    """A crash mid-append leaves a fragment: its beginning (no newline), or, when its first page never
    reached the disk, its end after zeros.  Neither was reported; both load as the entries before them."""
    path, clf = _journalled(tmp_path, n=4)
    journal = journal_path(path)
    clean = journal.read_bytes()
    body = clean.rstrip(b"\0")
    fragment = b'{"version": 5, "new_classes": [], "rows": [0, 1], "weights": [[0.25, 1.5'
    journal.write_bytes(body + fragment + bytes(8192))
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())
    journal.write_bytes(body + bytes(100) + b'5, 2.0]], "updates": 5}\n' + bytes(8192))
    assert json.dumps(load_model(path).state()) == json.dumps(clf.state())


# ------------------------------------------------------------ one writer


def test_a_second_store_on_one_model_file_is_refused_naming_the_first(tmp_path):
    path = tmp_path / "model.json"
    first = ModelStore(path, holder="/left/classifier_node")
    assert first.open() is None and first.locked
    with pytest.raises(ModelError, match=rf"in use by /left/classifier_node \(pid {os.getpid()} on "):
        ModelStore(path, holder="/right/classifier_node").open()
    with pytest.raises(ModelError, match="in use by /left/classifier_node"):
        save_model(OnlineClassifier(["A_x"]), path)
    first.close()
    second = ModelStore(path, holder="/right/classifier_node")
    second.open()
    second.close()


_COMPACTING = """
import sys
import numpy as np
from tactile_descriptors_ros.core.learning import OnlineClassifier
from tactile_descriptors_ros.core.model_store import ModelStore
clf = OnlineClassifier([f"A_{i}" for i in range(200)])
rng = np.random.default_rng(0)
for c in range(300):
    clf.pa.add_class(f"class_{c}")
clf.pa.weights = rng.standard_normal(clf.pa.weights.shape)
store = ModelStore(sys.argv[1], holder="compacting child")
store.open()
store.save(clf)
print("saved", flush=True)
while True:
    store.save(clf)
"""


def test_a_kill_during_compaction_leaves_no_temp_file_behind(tmp_path):
    """A process rewriting a 1 MB model in a loop is SIGKILLed while its temp file exists, three times:
    at most the one fixed temp name is ever there, the next open removes it, and the model loads."""
    import signal
    import subprocess
    import sys
    import time

    from tactile_descriptors_ros.core.model_store import temp_path

    path = tmp_path / "model.json"
    for _ in range(3):
        proc = subprocess.Popen([sys.executable, "-c", _COMPACTING, str(path)], stdout=subprocess.PIPE, text=True,
                                env={**os.environ, "PYTHONPATH": os.getcwd()})
        try:
            assert proc.stdout.readline() == "saved\n"  # one whole rewrite done: the loop of rewrites runs
            deadline = time.monotonic() + 60
            while not temp_path(path).exists() and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.001)  # polling the folder for the event: the temp file being written
            assert temp_path(path).exists(), "the child never wrote its temp file"
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
            proc.stdout.close()
        strays = [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
        assert strays in ([], [temp_path(path).name])
    store = ModelStore(path)
    model = store.open()
    assert model is not None and len(model.classes) == 300
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json", "model.json.lock"]
    assert store.strays_removed == [temp_path(path)]
    store.close()
