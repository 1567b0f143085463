"""Mapping files: a small declarative description of how a lab's recordings are laid out.

A mapping (YAML) says which file format holds the trials, where the class
and trial of each trial come from, and which column (CSV), array (NPZ) or
dataset (HDF5) is which BioTac channel.  The schema is documented in
``lab/docs/import.md``; every key is checked, and a misspelt key is named with
the closest valid one.  Mappings shipped with the package live in
``datasets/mappings/`` and are found by name (``biotac_slide_20_50``).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from tactile_descriptors_ros.core.cell_types import CellType
from tactile_descriptors_ros.errors import ConfigError

__all__ = ["Mapping", "NameRule", "Stamps", "FORMATS", "NPY_AXES", "TARE_MODES", "shipped_mappings", "load_mapping",
           "parse_mapping", "expand_channel"]

#: Table and bag formats a mapping can describe.
FORMATS = ("csv", "npz", "hdf5", "npy", "bag")
#: Axes an ``.npy`` array's ``shape`` description may name (``frame`` and ``column`` required).
NPY_AXES = ("trial", "frame", "column")
#: ``tare``: ``auto`` tares a trial whose resting PDC is far from zero, ``per_trial`` always, ``none`` never.
TARE_MODES = ("auto", "per_trial", "none")
_FROM = {"class": ("folder", "file", "group", "column", "option", "message"),
         "trial": ("folder", "file", "group", "column", "order")}
_UNITS_NS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
_TOP_KEYS = ("format", "files", "groups", "class", "trial", "samples_per_frame", "channels", "stamps", "tare",
             "sensor", "topic", "robot", "cell_type", "description", "shape", "columns", "labels", "counts_per_unit")
_RULE_KEYS = ("from", "pattern", "column", "value", "names", "number")
_CHANNEL_KEYS = ("pac", "pdc", "tac", "tdc", "electrodes")
_STAMP_KEYS = ("column", "unit", "rate_hz")
_MAPPINGS_DIR = Path(__file__).resolve().parent / "mappings"


@dataclass(frozen=True)
class NameRule:
    """Where a class or trial comes from.

    Attributes
    ----------
    source : str
        ``folder`` (the trial file's parent folder name), ``file`` (its name
        without suffix), ``group`` (HDF5 group path), ``column`` (a table
        column; a table then holds one trial per run of equal values),
        ``option`` (a fixed value), ``message`` (bags that carry it),
        ``order`` (trials numbered 1.. in sorted order, per class).
    pattern : re.Pattern or None
        Searched in the name; its group ``class`` (or ``trial``), else the
        first group, else the whole match, is the value.
    column : str or None
    value : str or None
    names : dict of str to str
        Value -> class name (a data set whose names are numbers).
    number : str or None
        A trial number built from several groups of ``pattern``: a format
        string over the groups in order, numbers as ``int``
        (``"{0}{1:02d}"``: session 3, run 7 -> trial 307), so that a run
        missing from the data leaves a gap instead of renumbering the rest.
    """

    source: str
    pattern: re.Pattern | None = None
    column: str | None = None
    value: str | None = None
    names: dict[str, str] = field(default_factory=dict)
    number: str | None = None

    def extract(self, text: str, what: str, where: str) -> str:
        """The value of this rule in ``text`` (a folder, file or group name)."""
        if self.pattern is None:
            return text
        m = self.pattern.search(text)
        if m is None:
            raise ConfigError(f"{where}: {what}.pattern {self.pattern.pattern!r} does not match {text!r}",
                              key=f"{what}.pattern")
        if self.number is not None:
            parts = [int(g) if g is not None and g.isdigit() else g for g in m.groups()]
            try:
                value = self.number.format(*parts)
            except (IndexError, ValueError, TypeError) as exc:
                raise ConfigError(f"{where}: {what}.number {self.number!r} does not format the groups "
                                  f"{list(m.groups())} of {text!r} ({exc})", key=f"{what}.number") from None
            if not value.isdigit():
                raise ConfigError(f"{where}: {what}.number {self.number!r} gives {value!r} for {text!r}, "
                                  "not a number", key=f"{what}.number")
            return value
        if what in m.groupdict() and m.group(what) is not None:
            return m.group(what)
        return m.group(1) if m.groups() else m.group(0)


@dataclass(frozen=True)
class Stamps:
    """Frame time stamps: from a column (in ``unit``), from a frame rate, or the first stamp plus a rate."""

    column: str | None = None
    unit: str = "s"
    rate_hz: float | None = None

    @property
    def ns_per_unit(self) -> int:
        return _UNITS_NS[self.unit]


@dataclass(frozen=True)
class Mapping:
    """A parsed mapping file (see the module docstring and ``lab/docs/import.md``)."""

    format: str
    files: str
    class_rule: NameRule
    trial_rule: NameRule
    samples_per_frame: int = 22
    channels: dict[str, Any] = field(default_factory=dict)
    stamps: Stamps = Stamps(rate_hz=100.0)
    tare: str = "auto"
    groups: str | None = None
    sensor: int = 0
    topic: str | None = None
    source: str = "<mapping>"
    description: str = ""
    robot: str = "shadow_hand"
    cell: CellType | None = None
    shape: tuple[str, ...] = ()
    columns: tuple[str, ...] = ()
    labels: tuple[str, str] | None = None
    counts_per_unit: float | None = None

    @property
    def cell_type(self) -> str:
        """The cell type of the recordings (``biotac`` unless the mapping names another)."""
        return "biotac" if self.cell is None else self.cell.name


def shipped_mappings() -> dict[str, Path]:
    """Mappings shipped with the package, by name."""
    return {p.stem: p for p in sorted(_MAPPINGS_DIR.glob("*.yaml"))}


def _check_keys(d: Any, allowed: tuple[str, ...], prefix: str, source: str) -> dict:
    if not isinstance(d, dict):
        raise ConfigError(f"must be a mapping of keys, got {type(d).__name__}", key=prefix or None, source=source)
    for k in d:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), allowed, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ConfigError(f"unknown key{hint}; valid keys: {', '.join(allowed)}",
                              key=f"{prefix}.{k}" if prefix else str(k), source=source)
    return d


def _rule(d: Any, what: str, source: str) -> NameRule:
    if isinstance(d, str):
        d = {"from": d}
    d = _check_keys(d, _RULE_KEYS, what, source)
    src = d.get("from")
    if src not in _FROM[what]:
        raise ConfigError(f"must be one of {', '.join(_FROM[what])}, got {src!r}", key=f"{what}.from", source=source)
    pattern = None
    if d.get("pattern") is not None:
        try:
            pattern = re.compile(str(d["pattern"]))
        except re.error as exc:
            raise ConfigError(f"bad regular expression: {exc}", key=f"{what}.pattern", source=source) from None
    if src == "column" and not d.get("column"):
        raise ConfigError("'from: column' needs the column's name", key=f"{what}.column", source=source)
    if src == "option" and d.get("value") is None:
        raise ConfigError("'from: option' needs a value", key=f"{what}.value", source=source)
    names = d.get("names") or {}
    if not isinstance(names, dict):
        raise ConfigError("must map values to class names", key=f"{what}.names", source=source)
    number = d.get("number")
    if number is not None:
        if not isinstance(number, str) or "{" not in number:
            raise ConfigError(f"must be a format of the pattern's groups such as '{{0}}{{1:02d}}', got {number!r}",
                              key=f"{what}.number", source=source)
        if pattern is None or pattern.groups < 1:
            raise ConfigError("'number' formats the groups of a pattern: give a pattern with groups",
                              key=f"{what}.pattern", source=source)
    return NameRule(source=src, pattern=pattern, column=d.get("column"),
                    value=None if d.get("value") is None else str(d["value"]),
                    names={str(k): str(v) for k, v in names.items()}, number=number)


def parse_mapping(data: Any, source: str = "<mapping>") -> Mapping:
    """Check and parse the contents of a mapping file.

    Raises
    ------
    ConfigError
        Naming the offending key (an unknown key, a missing one, a bad value).
    """
    d = _check_keys(data, _TOP_KEYS, "", source)
    fmt = d.get("format")
    if fmt not in FORMATS:
        raise ConfigError(f"must be one of {', '.join(FORMATS)}, got {fmt!r}", key="format", source=source)
    if "class" not in d:
        raise ConfigError("missing: say where the class comes from (folder, file, group, column, option)",
                          key="class", source=source)
    class_rule = _rule(d["class"], "class", source)
    trial_rule = _rule(d.get("trial", "order"), "trial", source)
    spf = d.get("samples_per_frame", 22)
    if not isinstance(spf, int) or isinstance(spf, bool) or spf < 1:
        raise ConfigError(f"must be a positive integer, got {spf!r}", key="samples_per_frame", source=source)
    robot, cell = _cell(d, fmt, source)
    if cell is None:
        channels = _check_keys(d.get("channels", {}), _CHANNEL_KEYS, "channels", source)
        required = _CHANNEL_KEYS if fmt != "bag" else ()
    else:
        channels = _check_keys(d.get("channels", {}), cell.channels, "channels", source)
        required = cell.vibration.channels + cell.deformation.channels
        if "samples_per_frame" not in d:
            spf = max(1, int(round(cell.vibration.rate_hz / cell.deformation.rate_hz)))
    for k in required:
        if k not in channels:
            raise ConfigError("missing channel", key=f"channels.{k}", source=source)
    for k, v in channels.items():
        if not (isinstance(v, str) or (isinstance(v, list) and all(isinstance(x, str) for x in v))):
            raise ConfigError("must be a column name, a name with {i}, or a list of names",
                              key=f"channels.{k}", source=source)
    stamps_d = _check_keys(d.get("stamps", {"rate_hz": 100.0}), _STAMP_KEYS, "stamps", source)
    unit = stamps_d.get("unit", "s")
    if unit not in _UNITS_NS:
        raise ConfigError(f"must be one of {', '.join(_UNITS_NS)}, got {unit!r}", key="stamps.unit", source=source)
    rate = stamps_d.get("rate_hz")
    if rate is not None and (not isinstance(rate, (int, float)) or isinstance(rate, bool) or not rate > 0):
        raise ConfigError(f"must be a positive number, got {rate!r}", key="stamps.rate_hz", source=source)
    if fmt != "bag" and stamps_d.get("column") is None and rate is None:
        raise ConfigError("give a time stamp column, a frame rate (rate_hz), or both", key="stamps", source=source)
    tare = d.get("tare", "auto")
    if tare not in TARE_MODES:
        raise ConfigError(f"must be one of {', '.join(TARE_MODES)}, got {tare!r}", key="tare", source=source)
    files = d.get("files")
    if fmt != "bag" and not isinstance(files, str):
        raise ConfigError("missing: a glob of the trial files below the data folder (e.g. '*/*.csv')",
                          key="files", source=source)
    sensor = d.get("sensor", 0)
    if not isinstance(sensor, int) or isinstance(sensor, bool) or sensor < 0:
        raise ConfigError(f"must be a sensor index >= 0, got {sensor!r}", key="sensor", source=source)
    shape, columns, labels = _npy_keys(d, fmt, source)
    cpu = d.get("counts_per_unit")
    if cpu is not None and (not isinstance(cpu, (int, float)) or isinstance(cpu, bool) or not cpu > 0):
        raise ConfigError(f"must be a positive number (counts per unit of the stored values), got {cpu!r}",
                          key="counts_per_unit", source=source)
    return Mapping(format=fmt, files=files or "**/*", class_rule=class_rule, trial_rule=trial_rule,
                   samples_per_frame=spf, channels=dict(channels),
                   stamps=Stamps(column=stamps_d.get("column"), unit=unit,
                                 rate_hz=None if rate is None else float(rate)),
                   tare=tare, groups=d.get("groups"), sensor=sensor, topic=d.get("topic"), source=source,
                   description=str(d.get("description", "")), robot=robot, cell=cell, shape=shape, columns=columns,
                   labels=labels, counts_per_unit=None if cpu is None else float(cpu))


def _npy_keys(d: dict, fmt: str, source: str) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, str] | None]:
    """``shape``, ``columns`` and ``labels``: the description of ``.npy`` arrays (format npy only)."""
    if fmt != "npy":
        for k in ("shape", "columns", "labels"):
            if k in d:
                raise ConfigError(f"describes .npy arrays: only with format npy (this mapping reads {fmt})",
                                  key=k, source=source)
        return (), (), None
    shape = d.get("shape")
    if (not isinstance(shape, list) or any(a not in NPY_AXES for a in shape) or len(set(shape)) != len(shape)
            or not {"frame", "column"} <= set(shape)):
        raise ConfigError(f"the axes of each array in order, from {', '.join(NPY_AXES)} (frame and column "
                          f"required), e.g. [trial, frame, column]; got {shape!r}", key="shape", source=source)
    cols = d.get("columns")
    names: list[str] = []
    if not isinstance(cols, list) or not cols:
        raise ConfigError("the name of each column of the arrays, in order: a name, or {name: 'e{i}', count: 19} "
                          "for numbered ones", key="columns", source=source)
    for i, c in enumerate(cols):
        if isinstance(c, str):
            names.append(c)
        elif isinstance(c, dict) and set(c) == {"name", "count"} and isinstance(c["name"], str) \
                and "{i}" in c["name"] and isinstance(c["count"], int) and c["count"] > 0:
            names.extend(expand_channel(c["name"], c["count"]))
        else:
            raise ConfigError(f"a column name, or {{name: 'e{{i}}', count: 19}}; got {c!r}", key=f"columns[{i}]",
                              source=source)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ConfigError(f"column {dup[0]!r} named twice", key="columns", source=source)
    labels = d.get("labels")
    if labels is not None:
        rep = labels.get("replace") if isinstance(labels, dict) and set(labels) == {"replace"} else None
        if not (isinstance(rep, list) and len(rep) == 2 and all(isinstance(x, str) and x for x in rep)):
            raise ConfigError("the file of each array's class labels (one a trial), as {replace: [from, to]} on "
                              "the array's file name, e.g. {replace: [X_, y_]}", key="labels", source=source)
        if "trial" not in shape:
            raise ConfigError("labels name one class a trial: the arrays need a trial axis", key="labels",
                              source=source)
        labels = (rep[0], rep[1])
    return tuple(shape), tuple(names), labels


def _cell(d: dict, fmt: str, source: str) -> tuple[str, CellType | None]:
    """``robot`` and ``cell_type``: the robot description declaring the recordings' cell type.

    No ``robot`` and no ``cell_type``, or the BioTac: ``None`` (the BioTac
    channels ``pac pdc tac tdc electrodes``).  Otherwise the cell type, whose
    channel names the ``channels`` keys are.
    """
    from tactile_descriptors_ros.core.robot import load_robot

    if "robot" not in d and "cell_type" not in d:
        return "shadow_hand", None
    name = d.get("robot", "shadow_hand" if d.get("cell_type") == "biotac" else None)
    if not isinstance(name, str) or not name:
        raise ConfigError("name the robot description that declares the cell type (a shipped robot such as nao, "
                          "or a robot description file)", key="robot", source=source)
    if not Path(name).is_absolute() and name.endswith((".yaml", ".yml")):
        name = str(Path(source).parent / name)  # a robot file beside the mapping
    try:
        robot = load_robot(name)
    except ConfigError as exc:
        raise ConfigError(str(exc), key="robot", source=source) from None
    ct_name = d.get("cell_type")
    if ct_name is None:
        if len(robot.cell_types) != 1:
            raise ConfigError(f"robot {robot.name!r} declares cell types {', '.join(robot.cell_types)}: "
                              "name one", key="cell_type", source=source)
        ct_name = next(iter(robot.cell_types))
    if ct_name not in robot.cell_types:
        raise ConfigError(f"robot {robot.name!r} declares no cell type {ct_name!r} (it has "
                          f"{', '.join(robot.cell_types)})", key="cell_type", source=source)
    if ct_name == "biotac":
        return name, None
    if fmt == "bag":
        raise ConfigError(f"bags hold BioTac messages; cell type {ct_name!r} is read from tables (csv, npz, hdf5)",
                          key="cell_type", source=source)
    return name, robot.cell_types[ct_name]


def load_mapping(name_or_path: str | Path) -> Mapping:
    """Read a mapping file, or a shipped mapping by name.

    Raises
    ------
    ConfigError
        For a missing file, bad YAML, or a bad key (named).
    """
    text = str(name_or_path)
    shipped = shipped_mappings()
    path = shipped[text] if text in shipped else Path(text)
    if not path.is_file():
        raise ConfigError(f"no mapping file {text!r} (shipped mappings: {', '.join(shipped) or 'none'})",
                          key="mapping")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigError(f"not a YAML mapping: {str(exc).splitlines()[0]}", source=str(path)) from None
    return parse_mapping(data, source=str(path))


def expand_channel(spec: str | list[str], count: int) -> list[str]:
    """Column names of a channel: a list as is, ``"pac{i}"`` -> ``pac1 .. pac<count>``, a plain name alone."""
    if isinstance(spec, list):
        return list(spec)
    if "{i}" in spec:
        return [spec.replace("{i}", str(i)) for i in range(1, count + 1)]
    return [spec]
