"""Read BioTac trials from tables (CSV, NPZ, HDF5) as a mapping file describes them.

A *unit* is what one trial (or, with a class or trial column, several) is
read from: a CSV or NPZ file, or one group of an HDF5 file.  Each unit is
read into a :class:`Table` (column name -> array) and cut into trials; the
mapping says which column is which channel (see :mod:`.mapping`).
"""

from __future__ import annotations

import csv
import io
import posixpath
import re
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.mapping import Mapping, expand_channel
from tactile_descriptors_lab.datasets.recording import N_ELECTRODES
from tactile_descriptors_ros.errors import ConfigError, DataFormatError

__all__ = ["Unit", "Table", "find_units", "read_table", "table_channels", "cell_channels", "frame_stamps_ns",
           "seconds_to_ns", "natural_key", "group_glob", "mapped_names"]


def natural_key(text: str) -> tuple:
    """Sort key that orders the numbers inside a name by value: ``run_9`` before ``run_10``, ``9.bag`` before
    ``10.bag`` (plain string order puts ``10`` first)."""
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p) for p in re.split(r"(\d+)", str(text)) if p)


def group_glob(pattern: str) -> re.Pattern:
    """A glob of HDF5 group paths as a regular expression: ``*`` and ``?`` stay inside one level (they do
    not match ``/``), ``**`` matches any number of levels, ``[...]`` a set of characters.

    :mod:`fnmatch` lets ``*`` match ``/`` too, so ``groups: "*"`` would pick every nested group
    (``run_1/finger_0``) as a trial of its own; this is the shell's path glob instead.
    """
    out, i, n = [], 0, len(pattern)
    while i < n:
        c = pattern[i]
        if pattern.startswith("**/", i):
            out.append("(?:.*/)?")
            i += 3
        elif pattern.startswith("**", i):
            out.append(".*")
            i += 2
        elif c == "*":
            out.append("[^/]*")
            i += 1
        elif c == "?":
            out.append("[^/]")
            i += 1
        elif c == "[" and "]" in pattern[i + 2:]:
            j = pattern.index("]", i + 2)
            body = pattern[i + 1:j]
            out.append("[" + ("^" + body[1:] if body.startswith("!") else body).replace("\\", "\\\\") + "]")
            i = j + 1
        else:
            out.append(re.escape(c))
            i += 1
    return re.compile("".join(out) + r"\Z")


@dataclass(frozen=True)
class Unit:
    """A file (or an HDF5 group of it) holding trials."""

    file: Path
    group: str | None = None

    @property
    def path(self) -> str:
        return f"{self.file}#{self.group}" if self.group else str(self.file)

    def name_of(self, source: str, what: str) -> str:
        """The folder, file or group name a class or trial rule reads."""
        if source == "folder":
            return self.file.parent.name
        if source == "file":
            return self.file.name.split(".", 1)[0] if self.file.suffix else self.file.name
        if source == "group":
            if self.group is None:
                raise ConfigError(f"{self.file}: {what} from 'group' needs an HDF5 file with groups",
                                  key=f"{what}.from")
            return self.group
        raise ValueError(source)


class Table:
    """Columns of one unit, by name (arrays of one row per frame, or 2-D for NPZ/HDF5 channels)."""

    def __init__(self, columns: dict[str, np.ndarray], where: str, text: bool) -> None:
        self.columns = columns
        self.where = where
        self.text = text  # CSV: values are strings until converted

    @property
    def n_rows(self) -> int:
        return int(next(iter(self.columns.values())).shape[0]) if self.columns else 0

    def column(self, name: str, key: str) -> np.ndarray:
        if name not in self.columns:
            raise DataFormatError(f"{self.where}: no column {name!r} (mapping key {key}); the file has "
                                  f"{_list(self.columns)}")
        return self.columns[name]

    def rows(self, sel: np.ndarray) -> Table:
        return Table({k: v[sel] for k, v in self.columns.items()}, self.where, self.text)


def _list(names) -> str:
    names = list(names)
    return ", ".join(names[:12]) + (f" ... ({len(names)} in all)" if len(names) > 12 else "")


def find_units(root: Path, mapping: Mapping) -> list[Unit]:
    """Units below ``root`` (or ``root`` itself when it is a file), sorted by path.

    Raises
    ------
    DataFormatError
        When nothing matches the mapping's ``files`` glob.
    """
    if root.is_file():
        files = [root]
    elif root.is_dir():
        files = sorted((p for p in root.glob(mapping.files) if p.is_file()), key=lambda p: natural_key(str(p)))
    else:
        raise DataFormatError(f"{root}: no such file or folder")
    if not files:
        there = sorted((str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()), key=natural_key)
        raise DataFormatError(f"{root}: no files match {mapping.files!r} (mapping key files, {mapping.source}); "
                              f"the folder holds {_list(there) or 'no file'}")
    if mapping.format != "hdf5":
        return [Unit(f) for f in files]
    h5py = _h5py()
    units = []
    for f in files:
        try:
            with h5py.File(f, "r") as h5:
                groups: list[str] = []
                h5.visititems(lambda name, obj, found=groups: found.append(name) if isinstance(obj, h5py.Group) else None)
        except OSError as exc:
            raise DataFormatError(f"{f}: not an HDF5 file ({exc})") from None
        if mapping.groups is None:
            units.append(Unit(f))
            continue
        glob = group_glob(mapping.groups)
        chosen = sorted((g for g in groups if glob.match(g)), key=natural_key)
        if not chosen:
            raise DataFormatError(f"{f}: no group matches {mapping.groups!r} (mapping key groups); groups: "
                                  f"{_list(groups) or 'none'}")
        units.extend(Unit(f, g) for g in chosen)
    return units


def _h5py():
    try:
        import h5py
    except ImportError:
        raise ConfigError("reading HDF5 needs h5py: pip install 'tactile_descriptors_ros[import]' "
                          "(or pip install h5py)", key="format") from None
    return h5py


def _read_csv(path: Path) -> Table:
    raw = path.read_bytes()
    if b"\x00" in raw[:65536]:
        raise DataFormatError(f"{path}: binary data, not a CSV text file")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataFormatError(f"{path}: not a UTF-8 text file (byte {exc.start}); is it a CSV table?") from None
    rows = list(csv.reader(io.StringIO(text)))
    rows = [r for r in rows if r and any(x.strip() for x in r)]
    if not rows:
        raise DataFormatError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    while header and header[-1] == "":
        header.pop()  # a trailing comma on every line
    body = rows[1:]
    if not body:
        raise DataFormatError(f"{path}: a header but no rows")
    n = len(header)
    for lineno, r in enumerate(body, start=2):
        if len(r) > n and not any(x.strip() for x in r[n:]):
            del r[n:]
        if len(r) != n:
            raise DataFormatError(f"{path}:{lineno}: {len(r)} fields, the header has {n}")
    # Columns of Python strings (object arrays): converting those to int64 is several times faster than
    # numpy's fixed-width unicode arrays.
    return Table({h: np.array(col, dtype=object) for h, col in zip(header, zip(*body))}, str(path), True)


def _read_npz(path: Path) -> Table:
    try:
        with np.load(path, allow_pickle=False) as z:
            cols = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise DataFormatError(f"{path}: not an NPZ archive ({str(exc).splitlines()[0]})") from None
    return Table(cols, str(path), False)


def mapped_names(mapping: Mapping) -> list[str]:
    """Every column name the mapping refers to (channels with ``{i}`` expanded to their first name), in
    mapping order: the channels, the stamp column, a class or trial column."""
    names: list[str] = []
    for spec in mapping.channels.values():
        names.extend(expand_channel(spec, 1) if isinstance(spec, str) else spec)
    if mapping.stamps.column is not None:
        names.append(mapping.stamps.column)
    for rule in (mapping.class_rule, mapping.trial_rule):
        if rule.source == "column" and rule.column:
            names.append(rule.column)
    return names


def _read_hdf5(unit: Unit, mapping: Mapping | None = None) -> Table:
    """The datasets at and below a unit's group, by their paths relative to it (``pdc``, ``finger_0/pac``).

    A name of the mapping that starts with ``../`` (or ``/``) is a dataset above the group, relative to it
    (or to the file's root): a run's ``../timestamps`` shared by the groups of its sensors.  The columns the
    mapping names come first, so the frame count is that of the mapping's channels, not of another
    sensor's dataset recorded at its own rate below the same group.
    """
    h5py = _h5py()
    wanted = mapped_names(mapping) if mapping is not None else []
    try:
        with h5py.File(unit.file, "r") as h5:
            node = h5[unit.group] if unit.group else h5
            found: dict[str, np.ndarray] = {}

            def visit(name: str, obj) -> None:
                if isinstance(obj, h5py.Dataset):
                    found[name] = obj

            node.visititems(visit)
            above = {}
            for name in wanted:
                if name.startswith(("../", "/")) and name not in found:
                    path = name if name.startswith("/") else posixpath.normpath(
                        posixpath.join("/" + (unit.group or ""), name))
                    obj = h5.get(path)
                    if isinstance(obj, h5py.Dataset):
                        above[name] = obj
            order = [n for n in wanted if n in found or n in above]
            order += [n for n in found if n not in order]
            cols = {n: np.asarray((found[n] if n in found else above[n])[()]) for n in order}
    except OSError as exc:
        raise DataFormatError(f"{unit.file}: not an HDF5 file ({exc})") from None
    for k, v in cols.items():
        if v.dtype.kind in "SO":
            cols[k] = v.astype(str)
    return Table(cols, unit.path, False)


def _read_npy(path: Path, mapping: Mapping) -> Table:
    """An ``.npy`` array as a table, its axes as the mapping's ``shape`` names them.

    The ``column`` axis gives the columns, named by the mapping's ``columns``; with a ``trial`` axis the
    rows are the frames of every trial in turn, with the column ``trial`` (1, 2, ... along that axis) and,
    with ``labels``, the column ``label`` (the labels file's value of each trial), so that
    ``trial: {from: column, column: trial}`` and ``class: {from: column, column: label}`` cut the trials.
    """
    def load(p: Path) -> np.ndarray:
        try:
            return np.load(p, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise DataFormatError(f"{p}: not an NPY array ({str(exc).splitlines()[0]})") from None

    arr = load(path)
    shape = mapping.shape
    if arr.ndim != len(shape):
        raise DataFormatError(f"{path}: an array of shape {arr.shape}, but the mapping's shape names "
                              f"{len(shape)} axes [{', '.join(shape)}] (mapping key shape, {mapping.source})")
    order = [a for a in ("trial", "frame", "column") if a in shape]
    arr = np.transpose(arr, [shape.index(a) for a in order])
    n_cols = arr.shape[-1]
    if n_cols != len(mapping.columns):
        raise DataFormatError(f"{path}: {n_cols} columns along axis {shape.index('column')} (shape {arr.shape}), "
                              f"the mapping names {len(mapping.columns)} (mapping key columns, {mapping.source})")
    n_trials = arr.shape[0] if "trial" in shape else 1
    n_frames = arr.shape[-2]
    flat = arr.reshape(n_trials * n_frames, n_cols)
    cols = {name: flat[:, i] for i, name in enumerate(mapping.columns)}
    if "trial" in shape:
        cols.setdefault("trial", np.repeat(np.arange(1, n_trials + 1), n_frames))
    if mapping.labels is not None:
        old, new = mapping.labels
        lpath = path.with_name(path.name.replace(old, new, 1))
        if lpath == path or not lpath.is_file():
            raise DataFormatError(f"{path}: no labels file {lpath.name} beside it (mapping key labels: replace "
                                  f"{old!r} by {new!r} in the file name)")
        lab = load(lpath)
        if lab.ndim != 1 or lab.shape[0] != n_trials:
            raise DataFormatError(f"{lpath}: labels of shape {lab.shape}, expected one a trial ({n_trials},) "
                                  f"for {path.name}")
        cols.setdefault("label", np.repeat(lab.astype(str), n_frames))
    return Table(cols, str(path), False)


def read_table(unit: Unit, fmt: str, mapping: Mapping | None = None) -> Table:
    """Read one unit's columns (HDF5: those below its group, and the ones above it that ``mapping`` names)."""
    if fmt == "npy":
        assert mapping is not None
        return _read_npy(unit.file, mapping)
    if fmt == "csv":
        return _read_csv(unit.file)
    if fmt == "npz":
        return _read_npz(unit.file)
    if fmt == "hdf5":
        return _read_hdf5(unit, mapping)
    raise ValueError(fmt)


def _as_counts(values: np.ndarray, table: Table, name: str, counts_per_unit: float | None = None) -> np.ndarray:
    """A column as int64 counts: integers as they are; with ``counts_per_unit``, stored values (floats in
    a unit: volts, normalised pressure) times that factor, rounded to the nearest count, as an ADC would."""
    try:
        if counts_per_unit is not None:
            v = np.asarray(values).astype(np.float64)
            if not np.all(np.isfinite(v)):
                raise ValueError("values that are not finite")
            return np.round(v * counts_per_unit).astype(np.int64)
        if table.text:
            return values.astype(np.int64)
        if values.dtype.kind == "f":
            if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
                raise ValueError("non-integer values; give counts_per_unit (mapping key) to scale stored values "
                                 "to counts")
            return values.astype(np.int64)
        return values.astype(np.int64)
    except ValueError as exc:
        raise DataFormatError(f"{table.where}: column {name!r}: not integer counts ({exc})") from None


def _channel(table: Table, mapping: Mapping, key: str, count: int) -> np.ndarray:
    """Counts of one channel, shape (n_frames, count)."""
    names = expand_channel(mapping.channels[key], count)
    if len(names) == 1 and count > 1:
        arr = _as_counts(table.column(names[0], f"channels.{key}"), table, names[0], mapping.counts_per_unit)
        if arr.ndim == 1 and arr.shape[0] == table.n_rows * count and not table.text:
            arr = arr.reshape(-1, count)
        if arr.ndim != 2 or arr.shape[1] != count:
            raise DataFormatError(f"{table.where}: {names[0]!r} (mapping key channels.{key}) has shape "
                                  f"{arr.shape}, expected (frames, {count})")
        return arr
    if len(names) != count:
        raise ConfigError(f"{len(names)} columns listed, {count} expected", key=f"channels.{key}",
                          source=mapping.source)
    missing = [n for n in names if n not in table.columns]
    if missing:
        raise DataFormatError(f"{table.where}: missing column{'s' if len(missing) > 1 else ''} "
                              f"{', '.join(missing)} (mapping key channels.{key}); the file has "
                              f"{_list(table.columns)}")
    cols = [_as_counts(table.columns[n], table, n, mapping.counts_per_unit) for n in names]
    for n, c in zip(names, cols):
        if c.ndim != 1:
            raise DataFormatError(f"{table.where}: {n!r} has shape {c.shape}, expected one value a frame")
    return np.stack(cols, axis=1)


def table_channels(table: Table, mapping: Mapping) -> dict[str, np.ndarray]:
    """PAC (n_frames, samples_per_frame), PDC/TAC/TDC (n_frames,) and electrodes (19, n_frames)."""
    pac = _channel(table, mapping, "pac", mapping.samples_per_frame)
    out = {"pac": pac}
    for key in ("pdc", "tac", "tdc"):
        out[key] = _channel(table, mapping, key, 1)[:, 0]
    out["electrodes"] = _channel(table, mapping, "electrodes", N_ELECTRODES).T.copy()
    n = {k: v.shape[-1] if k == "electrodes" else v.shape[0] for k, v in out.items()}
    if len(set(n.values())) != 1:
        raise DataFormatError(f"{table.where}: channels have different frame counts {n}")
    return out


def _values(table: Table, mapping: Mapping, key: str) -> np.ndarray:
    """One value a frame of channel ``key`` as float (an extra channel: proximity counts, degrees C, ...)."""
    names = expand_channel(mapping.channels[key], 1)
    if len(names) != 1:
        raise ConfigError(f"{len(names)} columns listed, 1 expected", key=f"channels.{key}", source=mapping.source)
    col = table.column(names[0], f"channels.{key}")
    try:
        v = np.asarray(col).astype(np.float64)
    except ValueError as exc:
        raise DataFormatError(f"{table.where}: column {names[0]!r} (mapping key channels.{key}): not numbers "
                              f"({exc})") from None
    if v.ndim != 1:
        raise DataFormatError(f"{table.where}: {names[0]!r} (mapping key channels.{key}) has shape {v.shape}, "
                              "expected one value a frame")
    return v


def cell_channels(table: Table, mapping: Mapping) -> dict[str, np.ndarray]:
    """The channels of a mapping's cell type (``mapping.cell``, a skin cell ...) from one table.

    Returns
    -------
    dict
        ``vibration`` (n_s, n_frames * samples_per_frame) int64 counts, one
        row a vibration channel, samples in time order; ``deformation``
        (n_v, n_frames) int64 counts; ``extra`` (n_extra, n_frames) float64,
        NaN for an extra channel the mapping does not name; ``absent`` the
        extra channels it does not name.

    Raises
    ------
    DataFormatError
        Naming the file, the column and the mapping key of a channel the
        table lacks, or whose values are not integer counts.
    """
    ct = mapping.cell
    assert ct is not None
    k = mapping.samples_per_frame
    dfm = np.stack([_channel(table, mapping, c, 1)[:, 0] for c in ct.deformation.channels])
    n = dfm.shape[1]
    vib = (np.stack([_channel(table, mapping, c, k).reshape(-1) for c in ct.vibration.channels])
           if ct.has_vibration else np.zeros((0, n * k), dtype=np.int64))  # pressure only
    absent = tuple(c for c in ct.extra_channels if c not in mapping.channels)
    extra = np.full((len(ct.extra_channels), n), np.nan)
    for i, c in enumerate(ct.extra_channels):
        if c not in absent:
            extra[i] = _values(table, mapping, c)
    if vib.shape[1] != n * k:
        raise DataFormatError(f"{table.where}: {vib.shape[1]} vibration samples for {n} frames of {k}")
    return {"vibration": vib, "deformation": dfm, "extra": extra, "absent": absent}


def seconds_to_ns(text: str, ns_per_unit: int = 1_000_000_000) -> int:
    """Exact conversion of a decimal time string (in a unit of ``ns_per_unit`` ns) to integer ns."""
    t = text.strip()
    neg = t.startswith("-")
    whole, _, frac = t.lstrip("+-").partition(".")
    digits = len(str(ns_per_unit)) - 1
    frac = (frac + "0" * digits)[:digits] if digits else ""
    try:
        v = int(whole or "0") * ns_per_unit + (int(frac) if frac else 0)
    except ValueError:
        raise DataFormatError(f"bad time stamp {text!r}") from None
    return -v if neg else v


def frame_stamps_ns(table: Table, mapping: Mapping, n_frames: int) -> np.ndarray:
    """Frame stamps in ns: from the stamp column, a frame rate, or the first stamp plus the rate."""
    st = mapping.stamps
    first = 0
    stamps = None
    if st.column is not None:
        col = table.column(st.column, "stamps.column")
        if table.text:
            stamps = np.array([seconds_to_ns(v, st.ns_per_unit) for v in col], dtype=np.int64)
        elif col.dtype.kind in "iu":
            stamps = col.astype(np.int64) * st.ns_per_unit
        else:
            try:
                stamps = np.round(col.astype(np.float64) * st.ns_per_unit).astype(np.int64)
            except ValueError:
                raise DataFormatError(f"{table.where}: stamp column {st.column!r} is not numeric") from None
        first = int(stamps[0]) if stamps.size else 0
    if st.rate_hz is not None:
        return first + np.round(np.arange(n_frames) * (1e9 / st.rate_hz)).astype(np.int64)
    assert stamps is not None
    return stamps


def split_runs(keys: list[np.ndarray]) -> Iterator[np.ndarray]:
    """Index arrays of the runs of equal values across ``keys`` (each one value a row)."""
    n = keys[0].shape[0]
    change = np.zeros(n, dtype=bool)
    change[0] = True
    for k in keys:
        change[1:] |= k[1:] != k[:-1]
    starts = np.flatnonzero(change)
    ends = np.append(starts[1:], n)
    for s, e in zip(starts, ends):
        yield np.arange(s, e)
