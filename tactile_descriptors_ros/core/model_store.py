"""A classifier model on disk: the model file, its journal and its lock.

For a model file ``model.json`` (:meth:`~.learning.OnlineClassifier.state`
as JSON) three files live side by side:

* ``model.json``: the whole model, always replaced atomically (written to
  ``.model.json.tmp``, fsync, rename over the file, fsync of the folder);
* ``model.json.journal``: one line per label learned since the file was
  written (:meth:`~.learning.OnlineClassifier.delta`: what the update
  changed), each synced before the label is reported; its first line names
  the SHA-256 of the file it extends;
* ``model.json.lock``: locked (``flock``) by the one process that writes the
  model, and naming it (node, pid, host).  A second writer refuses to start,
  naming the first.  The file stays when the lock is released: it is the
  lock's name, not a temporary file.

Loading replays the journal onto the file.  Compaction writes the file
anew and starts an empty journal.  Every state a crash, a kill, a power loss
or a full disk leaves behind loads to a model holding every label that was
reported saved (see :class:`ModelStore`).  Damage that no crash makes (a
zeroed region or a garbled line followed by later entries) is refused,
naming the journal line; ``tactile model recover <model file>``
(:func:`recover_model`) keeps the entries before it and sets the damaged
journal aside.

This module holds every file operation of the classifier's model; the
learning algorithm (:mod:`.learning`) holds none.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import socket
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import ModelError
from .groups import groups_in_labels, selection_name
from .learning import OnlineClassifier

__all__ = ["ModelStore", "ModelLock", "JournalReport", "load_model", "save_model", "check_model", "recover_model",
           "journal_path", "lock_path", "temp_path", "layout_file_name", "RECOVER_COMMAND"]

_JOURNAL_FORMAT = "tactile_descriptors_ros/online_classifier_journal"

#: Journal extensions are whole pages of this many bytes.
_PAGE = 4096

#: The command that recovers a model whose journal is damaged in the middle (``docs/nodes.md``).
RECOVER_COMMAND = "tactile model recover"


def journal_path(path: str | os.PathLike[str]) -> Path:
    """The journal beside a model file: ``<model file>.journal``."""
    path = Path(path)
    return path.with_name(path.name + ".journal")


def lock_path(path: str | os.PathLike[str]) -> Path:
    """The lock file beside a model file: ``<model file>.lock``."""
    path = Path(path)
    return path.with_name(path.name + ".lock")


def temp_path(path: str | os.PathLike[str]) -> Path:
    """The one temporary file a rewrite of the model uses: ``.<model file name>.tmp``.

    One fixed name, written only by the lock's holder: a kill during a
    rewrite leaves at most this one file, which the next rewrite replaces and
    the next :meth:`ModelStore.open` removes.
    """
    path = Path(path)
    return path.with_name(f".{path.name}.tmp")


# --------------------------------------------------------------------- lock
class ModelLock:
    """An exclusive ``flock`` on ``<model file>.lock`` naming its holder (:meth:`acquire` raises ModelError naming
    the other holder).

    ``flock`` locks belong to the open file, so two stores in one process
    exclude each other too, and the kernel releases the lock when the
    process dies (a kill leaves no stale lock).
    """

    def __init__(self, model: Path, holder: str) -> None:
        self.model = model
        self.path = lock_path(model)
        self.holder = holder
        self._fd: int | None = None

    def acquire(self) -> None:
        if self._fd is not None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise ModelError(f"{self.model}: cannot open the lock file {self.path}: {exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            other = ""
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                try:
                    other = os.pread(fd, 4096, 0).decode("utf-8", "replace").strip()
                except OSError:
                    pass
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise ModelError(f"{self.model}: cannot lock {self.path}: {exc}") from None
            raise ModelError(f"model {self.model} is in use by {other or 'another process'}: two "
                             "classifiers must not learn into one file; give this one another model_path "
                             "(or another namespace)") from None
        info = f"{self.holder or 'a process'} (pid {os.getpid()} on {socket.gethostname()})\n".encode()
        try:  # who holds it, for the message above; a full disk must not stop the lock itself
            os.ftruncate(fd, 0)
            os.pwrite(fd, info, 0)
        except OSError:
            pass
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the only descriptor of the open file releases the flock
            self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __del__(self) -> None:  # a store dropped without close() must not keep its file locked
        self.release()


def _remove_strays(model: Path) -> list[Path]:
    """Remove temporary files a killed rewrite left (the fixed name, and the random names of older releases)."""
    removed = []
    for stray in [temp_path(model), *model.parent.glob(f".{model.name}.*.tmp")]:
        try:
            stray.unlink()
            removed.append(stray)
        except FileNotFoundError:
            pass
        except OSError:
            pass  # left for the next start; it is never read
    return removed


# ------------------------------------------------------------- whole file
def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` by ``data``: temp file, fsync, rename, fsync of the folder (caller holds the lock).

    Raises
    ------
    ModelError
        When writing fails (e.g. a full disk); ``path`` is then untouched and
        the temp file removed.
    """
    tmp = temp_path(path)
    renamed = False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
        try:
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
        renamed = True
        _fsync_dir(path.parent)  # make the rename itself survive a power loss
    except OSError as exc:
        if not renamed:
            try:
                tmp.unlink()
            except OSError:
                pass
            raise ModelError(f"cannot save model to {path}: {exc}") from None
        # renamed: every reader already sees the new file; only its survival of a power loss is in doubt
        raise _RenamedButNotSynced(f"saved {path}, but cannot sync its folder: {exc}") from None


class _RenamedButNotSynced(ModelError):
    """The new model file is in place, but the folder's sync failed (internal)."""


def _model_bytes(model: OnlineClassifier) -> bytes:
    return json.dumps(model.state()).encode()


def save_model(model: OnlineClassifier, path: str | os.PathLike[str], holder: str = "") -> None:
    """Write a whole model file atomically and drop its journal (offline tools; a node uses :class:`ModelStore`).

    Takes the model's lock for the write, so it refuses a file a running
    node holds.

    Raises
    ------
    ModelError
        If the file is locked by another process or cannot be written; the
        previous file is left untouched.
    """
    path = Path(path)
    lock = ModelLock(path, holder or "save_model")
    lock.acquire()
    try:
        try:
            _write_atomic(path, _model_bytes(model))
        except _RenamedButNotSynced:
            pass
        journal = journal_path(path)
        try:
            journal.unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:  # harmless: its header names another snapshot, so it is never replayed
            raise ModelError(f"saved {path}, but cannot remove the old journal {journal}: {exc}") from None
    finally:
        lock.release()


# ------------------------------------------------------------------ loading
@dataclass
class JournalReport:
    """What reading a journal found.

    Attributes
    ----------
    entries : int
        Entries applied.
    valid_bytes : int
        Bytes of the header and the applied entries (where the next entry goes).
    data_bytes : int
        Bytes up to the end of the last non-zero byte (a torn last entry included).
    extends_snapshot : bool
        The journal's header names the loaded model file (False: none, or stale).
    damaged_line : int or None
        The first line not applied because it is damaged (only when damage is tolerated).
    damage : str
        Why that line was not applied.
    """

    entries: int = 0
    valid_bytes: int = 0
    data_bytes: int = 0
    extends_snapshot: bool = False
    damaged_line: int | None = None
    damage: str = ""


def _looks_like_entry(segment: bytes) -> bool:
    try:
        return isinstance(json.loads(segment), dict)
    except ValueError:
        return False


def _read_journal(model: OnlineClassifier, model_path: Path, snapshot_sha256: str,
                  tolerate_damage: bool = False) -> JournalReport:
    """Apply a journal's entries to ``model`` (see the module docstring).

    A journal whose header names another snapshot is stale (the file was
    rewritten after it) and is skipped.  Entries end at the reserved zeros;
    a last entry without its newline (or, after the zeros, a fragment of one
    whose first page never reached the disk) is an append cut short by a
    crash: never reported, ignored.  Anything else that stops the entries
    short of later ones is damage: an error naming the line, or with
    ``tolerate_damage`` the point where reading stopped.
    """
    journal = journal_path(model_path)
    report = JournalReport()
    try:
        data = journal.read_bytes()
    except FileNotFoundError:
        return report
    except OSError as exc:
        raise ModelError(f"{journal}: cannot read journal: {exc}") from None
    report.data_bytes = len(data.rstrip(b"\0"))
    cut = data.find(b"\0")
    body = data if cut < 0 else data[:cut]
    lines = body.split(b"\n")[:-1]  # whole lines; the part after the last newline is torn (or empty)

    def damaged(number: int, what: str) -> JournalReport:
        kept = max(number - 2, 0)
        msg = (f"{journal}: line {number}: {what}; the journal is damaged, not cut short by a crash, and "
               f"nothing was loaded. `{RECOVER_COMMAND} {model_path}` keeps the model file and the {kept} "
               f"entr{'y' if kept == 1 else 'ies'} before line {number}, and sets the damaged journal aside")
        if not tolerate_damage:
            raise ModelError(msg)
        report.damaged_line, report.damage = number, what
        return report

    if not lines:
        if report.data_bytes > len(body):
            return damaged(1, "the header is zeroed but data follows it")
        return report
    try:
        header = json.loads(lines[0])
    except ValueError as exc:
        return damaged(1, f"not JSON ({exc})")
    if not isinstance(header, dict) or header.get("format") != _JOURNAL_FORMAT:
        return damaged(1, "not a journal of this package")
    if header.get("snapshot_sha256") != snapshot_sha256:
        return report  # stale: written for an earlier file, whose rewrite already holds it
    report.extends_snapshot = True
    report.valid_bytes = len(lines[0]) + 1
    for number, line in enumerate(lines[1:], start=2):
        try:
            entry = json.loads(line)
        except ValueError as exc:
            return damaged(number, f"not JSON ({exc})")
        try:
            model.apply_delta(entry)
        except ModelError as exc:
            return damaged(number, str(exc))
        report.entries += 1
        report.valid_bytes += len(line) + 1
    # After the last whole line: a torn entry, zeros, and nothing else.  A whole entry after them means
    # the zeros (or the garbled bytes) replaced entries that had been reported saved.
    rest = data[report.valid_bytes:].rstrip(b"\0")
    if b"\n" in rest:
        segments = [s.strip(b"\0") for s in rest.split(b"\n")[:-1]]
        torn_fragment = len(segments) == 1 and rest.endswith(b"\n") and not _looks_like_entry(segments[0])
        if not torn_fragment:
            zeros = data.find(b"\0", report.valid_bytes)
            where = f"zeroed bytes at byte {zeros}" if 0 <= zeros < report.valid_bytes + len(rest) \
                else "a garbled entry"
            return damaged(len(lines) + 1, f"{where}, and {len(segments)} more line"
                                           f"{'s' if len(segments) > 1 else ''} after it")
    return report


def _load(path: Path, labels: Sequence[str] | None,
          tolerate_damage: bool = False) -> tuple[OnlineClassifier, bytes, JournalReport]:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise ModelError(f"{path}: cannot read model: {exc}") from None
    try:
        state = json.loads(raw)
    except ValueError as exc:
        raise ModelError(f"{path}: not JSON: {exc}") from None
    try:
        model = OnlineClassifier.from_state(state)
    except ModelError as exc:
        raise ModelError(f"{path}: {exc}") from None
    report = _read_journal(model, path, hashlib.sha256(raw).hexdigest(), tolerate_damage)
    if labels is not None and tuple(labels) != model.labels:
        raise ModelError(f"{path}: model was trained on another descriptor layout "
                         f"({len(model.labels)} values, first {model.labels[:2]}), not {len(labels)} values")
    return model, raw, report


def load_model(path: str | os.PathLike[str], labels: Sequence[str] | None = None) -> OnlineClassifier:
    """Load a model file and replay its journal, if any (read only: no lock, nothing written).

    With ``labels``, refuse a model of another descriptor layout.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ModelError
        Naming ``path`` (or the journal and its line) and what is wrong.
    """
    return _load(Path(path), labels)[0]


def check_model(path: str | os.PathLike[str]) -> tuple[OnlineClassifier, JournalReport]:
    """The model with every entry before any damage, and what reading the journal found (nothing written)."""
    model, _, report = _load(Path(path), None, tolerate_damage=True)
    return model, report


def recover_model(path: str | os.PathLike[str], holder: str = "tactile model recover") -> JournalReport:
    """Keep a model file and its journal's entries before the damage; set the damaged journal aside.

    The model with those entries is written as the new model file, and the
    journal is renamed ``<journal>.damaged`` (``.damaged.1``, ... when that
    exists) for inspection; nothing is deleted.  Takes the model's lock, so
    it refuses while a node holds the file.

    Raises
    ------
    ModelError
        If the file is locked, the model file itself is corrupt, or writing fails.
    """
    path = Path(path)
    lock = ModelLock(path, holder)
    lock.acquire()
    try:
        model, report = check_model(path)
        journal = journal_path(path)
        try:
            _write_atomic(path, _model_bytes(model))
        except _RenamedButNotSynced:
            pass
        if journal.exists():
            aside = journal.with_name(journal.name + ".damaged")
            n = 0
            while aside.exists():
                n += 1
                aside = journal.with_name(f"{journal.name}.damaged.{n}")
            try:
                if report.damaged_line:
                    os.replace(journal, aside)
                else:
                    journal.unlink()  # nothing damaged: the new file holds every entry
            except OSError as exc:
                raise ModelError(f"wrote {path}, but cannot move the journal {journal} aside: {exc}") from None
        _remove_strays(path)
        return report
    finally:
        lock.release()


# -------------------------------------------------------------------- store
class ModelStore:
    """A locked model file with an append-only journal: a durable save per label, at a cost independent of the classes.

    Rewriting the whole file costs 78 ms with 1,000 classes.  After each
    label the store instead writes one line holding exactly what the update
    changed (:meth:`~.learning.OnlineClassifier.delta`) into
    ``<model file>.journal`` and ``fdatasync`` s it: when :meth:`record`
    returns, the label survives a crash, a SIGKILL or a power loss.

    Guarantees:

    * **One writer**: :meth:`open` locks ``<model file>.lock`` (``flock``);
      a second store on the same file, in this process or another, is
      refused naming the holder.
    * **Durable before reported**: :meth:`record` returns only after the
      entry is on disk; report a label only after it returns.  When it
      raises (a full disk past the reserved space), the label is not saved,
      and the next entry is written at the same place.
    * **Atomic per label**: a crash mid-append leaves a torn last line, which
      loading ignores; the label is then wholly absent, never half applied.
    * **Compaction never risks a label**: once the journal outgrows the
      file (and ``min_compact_bytes``) the store rewrites the file (temp
      file, fsync, rename) and only then starts an empty journal.  If the
      rewrite fails (a full disk), the journal stays open and appendable,
      the failure is counted (:attr:`compaction_failures`,
      :attr:`compaction_error`) and compaction is tried again after the
      journal has grown by a quarter of the threshold.  The journal's first
      line names the SHA-256 of the file it extends, so a journal left
      behind between the rename and its removal is stale and never
      replayed twice.
    * **Starts on a full disk**: :meth:`open` replays the journal and
      compacts; if the rewrite fails, it appends to the journal where its
      entries end.
    * **No temporary files left**: rewrites use one fixed temp name
      (:func:`temp_path`), removed on failure and, after a kill, by the next
      :meth:`open`.
    * **Exact**: entries hold floats as JSON's shortest round-trip repr; the
      replayed model equals the one in memory bit for bit.
    * **Pre-sized**: the journal file is extended with written zeros ahead
      of its entries (``reserve_bytes`` at a time, at least four entries),
      and each entry is written over those zeros, so ``fdatasync`` flushes
      the entry's data only, without a filesystem metadata commit; only the
      extension, once per ``reserve_bytes``, syncs the size.  On a full disk
      the reserve still takes the entries that fit in it.

    Parameters
    ----------
    path : path-like
        The model file.
    holder : str
        Who holds the lock (a node's full name), for another writer's refusal.
    min_compact_bytes : int, default 1 MiB
        Never compact a journal smaller than this.
    reserve_bytes : int, default 256 KiB
        Zeros written ahead of the entries at a time (in whole 4 KiB pages);
        0 appends without reserving (every sync then also commits the size).
    """

    def __init__(self, path: str | os.PathLike[str], holder: str = "", min_compact_bytes: int = 1 << 20,
                 reserve_bytes: int = 1 << 18) -> None:
        self.path = Path(path)
        self.journal = journal_path(self.path)
        self.min_compact_bytes = int(min_compact_bytes)
        if reserve_bytes < 0:
            raise ValueError(f"reserve_bytes must not be negative, got {reserve_bytes}")
        self.reserve_bytes = int(reserve_bytes)
        self._lock = ModelLock(self.path, holder)
        self._fd: int | None = None
        self._reserved_bytes = 0  # the journal file's size: entries, then written zeros
        #: times the journal file was extended (created included)
        self.extensions = 0
        self._snapshot_bytes = 0
        self._snapshot_sha256 = ""
        self._journal_bytes = 0
        self._synced_version: int | None = None
        self._synced_classes = 0
        self._retry_compaction_at = 0
        #: successful compactions; failed ones, and the last failure's reason (None after a success)
        self.compactions = 0
        self.compaction_failures = 0
        self.compaction_error: str | None = None
        #: temporary files of killed rewrites removed by :meth:`open`
        self.strays_removed: list[Path] = []

    # ----------------------------------------------------------------- open
    def open(self, labels: Sequence[str] | None = None, load: bool = True) -> OnlineClassifier | None:
        """Lock the file, remove a killed rewrite's temp file, and load the model if it exists (and ``load``).

        Loading replays the journal and compacts it; if the rewrite fails
        (:attr:`compaction_error`), later entries are appended to the journal.

        Raises
        ------
        ModelError
            If another process holds the file, or the model or journal is
            corrupt (naming the file, line and key).
        """
        self._lock.acquire()
        self.strays_removed = _remove_strays(self.path)
        if not load or not self.path.is_file():
            return None
        model, raw, report = _load(self.path, labels)
        self._adopt(model, raw)
        if (report.entries or self.journal.exists()) and not self._compact(model) and report.extends_snapshot \
                and not self._reopen(report):
            # the journal holds entries the file lacks, and cannot be appended to: never start a new
            # journal over it; the next record rewrites the whole file instead
            self._synced_version = None
        return model

    @property
    def locked(self) -> bool:
        return self._lock.held

    def _reopen(self, report: JournalReport) -> bool:
        """Append to the existing journal after its last whole entry (a compaction at start failed)."""
        try:
            fd = os.open(self.journal, os.O_RDWR | os.O_CLOEXEC)
        except OSError:
            return False
        try:
            size = os.fstat(fd).st_size
            if report.data_bytes > report.valid_bytes:  # a torn entry: zero it, so it cannot join the next one
                os.pwrite(fd, bytes(report.data_bytes - report.valid_bytes), report.valid_bytes)
                _datasync(fd)
        except OSError:
            os.close(fd)
            return False
        self._fd = fd
        self._journal_bytes = report.valid_bytes
        self._reserved_bytes = size if self.reserve_bytes else report.valid_bytes
        return True

    # ---------------------------------------------------------------- write
    def save(self, model: OnlineClassifier) -> None:
        """Rewrite the whole file atomically and start an empty journal (``~/save``, compaction, reset).

        Raises
        ------
        ModelError
            If the rewrite fails; the file and the journal are then as they
            were, and :meth:`record` keeps appending to the journal.
        """
        self._lock.acquire()
        raw = _model_bytes(model)
        try:
            _write_atomic(self.path, raw)
        except _RenamedButNotSynced as exc:
            self._after_rewrite(model, raw)
            raise ModelError(str(exc)) from None
        self._after_rewrite(model, raw)

    def _after_rewrite(self, model: OnlineClassifier, raw: bytes) -> None:
        """The new file is in place: the journal is stale from here on; drop it and adopt the file."""
        self._close_journal()
        try:
            self.journal.unlink()
        except OSError:
            pass  # stale (its header names the previous file): never replayed, replaced by the next journal
        self._adopt(model, raw)

    def _compact(self, model: OnlineClassifier) -> bool:
        try:
            self.save(model)
        except ModelError as exc:
            self.compaction_failures += 1
            self.compaction_error = str(exc)
            self._retry_compaction_at = self._journal_bytes + self._compact_threshold() // 4
            return False
        self.compactions += 1
        self.compaction_error = None
        self._retry_compaction_at = 0
        return True

    def _compact_threshold(self) -> int:
        return max(self._snapshot_bytes, self.min_compact_bytes)

    def _adopt(self, model: OnlineClassifier, raw: bytes) -> None:
        self._snapshot_bytes = len(raw)
        self._snapshot_sha256 = hashlib.sha256(raw).hexdigest()
        self._journal_bytes = 0
        self._synced_version = model.version
        self._synced_classes = len(model.classes)

    def record(self, model: OnlineClassifier) -> None:
        """Make the last :meth:`~.learning.OnlineClassifier.learn` durable (one entry, synced).

        Falls back to :meth:`save` when the change is not one entry (no
        file yet, or several updates since the last record).  Compacts when
        the journal has outgrown the file; a failed compaction is counted,
        never raised: the label is durable in the journal.

        Raises
        ------
        ModelError
            When the entry could not be written (e.g. a full disk past the
            reserve); the label is then not durable.
        """
        self._lock.acquire()
        if self._synced_version is None or model.version != self._synced_version + 1 or not self.path.exists():
            self.save(model)
            return
        line = (json.dumps(model.delta(self._synced_classes)) + "\n").encode()
        try:
            if self._fd is None:
                self._start_journal(len(line))
            elif self._journal_bytes + len(line) > self._reserved_bytes:
                self._extend(len(line))
            self._pwrite(line, self._journal_bytes)
            _datasync(self._fd)  # over written zeros: the entry's data only, no metadata commit
        except OSError as exc:
            # the journal stays open (or, never started, is started by the next entry): the next entry
            # is written where this one failed
            raise ModelError(f"cannot append to the model journal {self.journal}: {exc}") from None
        self._journal_bytes += len(line)
        self._synced_version = model.version
        self._synced_classes = len(model.classes)
        if self._journal_bytes > self._compact_threshold() and self._journal_bytes >= self._retry_compaction_at:
            self._compact(model)

    def _start_journal(self, first_entry: int) -> None:
        """A new journal for the current file (only ever right after the file was written: no entry is lost)."""
        header = (json.dumps({"format": _JOURNAL_FORMAT, "snapshot_sha256": self._snapshot_sha256}) + "\n").encode()
        fd = os.open(self.journal, os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
        self._fd, self._reserved_bytes, self._journal_bytes = fd, 0, 0
        try:
            self._extend(len(header) + first_entry)
            self._pwrite(header, 0)
            _fsync_dir(self.path.parent)  # the journal's name itself must survive
        except OSError:
            self._close_journal()
            raise
        self._journal_bytes = len(header)

    @property
    def journal_bytes(self) -> int:
        """Bytes of the journal's header and entries (the file is longer by its reserved zeros)."""
        return self._journal_bytes

    def _extend(self, need: int) -> None:
        """Write zeros from the end of the entries to make room for ``need`` bytes and more; sync the new size."""
        if not self.reserve_bytes:
            return
        start = self._journal_bytes
        size = start + max(self.reserve_bytes, 4 * need)
        size = -(-size // _PAGE) * _PAGE
        zeros = bytes(min(size - start, 1 << 20))
        pos = start
        while pos < size:
            pos += os.pwrite(self._fd, zeros[:size - pos], pos)
        os.fsync(self._fd)  # the new size and blocks, once per reserve
        self._reserved_bytes = size
        self.extensions += 1

    def _pwrite(self, data: bytes, offset: int) -> None:
        view = memoryview(data)
        while view:
            n = os.pwrite(self._fd, view, offset)
            view, offset = view[n:], offset + n

    def reset(self) -> None:
        """Remove the model file and its journal (the caller forgets the model; the lock stays held)."""
        self._close_journal()
        for p in (self.path, self.journal):
            try:
                p.unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                raise ModelError(f"cannot remove {p}: {exc}") from None
        self._synced_version = None
        self._journal_bytes = 0

    def _close_journal(self) -> None:
        if self._fd is not None:
            try:
                os.close(self._fd)
            except OSError:
                pass
            self._fd = None

    def close(self) -> None:
        """Close the journal and release the lock (entries already recorded stay durable)."""
        self._close_journal()
        self._lock.release()


def _datasync(fd: int) -> None:
    """``fdatasync`` where the platform has it, else ``fsync``."""
    if hasattr(os, "fdatasync"):
        os.fdatasync(fd)
    else:  # pragma: no cover - macOS
        os.fsync(fd)


def _fsync_dir(folder: Path) -> None:
    """fsync a folder so a rename inside it is on disk (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def layout_file_name(labels: Sequence[str]) -> str:
    """A model file name for a descriptor layout: its body parts, feature groups, value count and hash.

    ``index.per_channel+bands+levels+statistics.261v.3fa2b1c0d9.json``: two
    layouts (e.g. the concatenated descriptor of one window node and the
    pooled ones of a window node per body part) never share a file, and
    the name says which is which.
    """
    parts = "+".join(dict.fromkeys(lab.split("/", 1)[0] for lab in labels if "/" in lab)) or "all"
    digest = hashlib.sha256("\n".join(labels).encode()).hexdigest()[:10]
    name = f"{parts[:40]}.{selection_name(groups_in_labels(labels))[:60]}.{len(labels)}v.{digest}.json"
    return "".join(c if c.isalnum() or c in "._+-" else "_" for c in name)
