"""One reader for every recording ``tactile import`` and ``tactile evaluate`` accept.

:func:`read_source` turns a folder or file (tables described by a mapping,
or ROS 1/ROS 2 bags) into :class:`~.recording.BiotacRecording` objects:

1. the mapping (a shipped name or a file; for a bag, the bag default) says
   where trials are and which column is which channel;
2. each trial's class and trial number come from the data (a folder, file
   or group name by pattern, a label column, the bag's labels) or from an
   option (``class_name``);
3. a trial whose resting PDC is far from zero is tared (``tare: auto``),
   and :class:`LoadReport` says which;
4. a trial or class selection that names what the data do not hold is an
   error listing what exists.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.bagfiles import find_bags, is_bag, read_bag_frames
from tactile_descriptors_lab.datasets.mapping import Mapping, NameRule, load_mapping, parse_mapping
from tactile_descriptors_lab.datasets.recording import (
    UNTARED_REST_COUNTS,
    BiotacRecording,
    CellRecording,
    spread_pac_stamps,
    tare_recording,
    trial_rest,
)
from tactile_descriptors_lab.datasets.tables import (
    Unit,
    cell_channels,
    find_units,
    frame_stamps_ns,
    natural_key,
    read_table,
    split_runs,
    table_channels,
)
from tactile_descriptors_ros.core.tare import TRIAL_REST_PERCENTILE, resting_level
from tactile_descriptors_ros.errors import ConfigError, DataFormatError, SignalError

__all__ = ["DEFAULT_MAPPING", "BAG_MAPPING", "LoadReport", "read_source", "resolve_mapping", "check_selection",
           "format_numbers", "align_classes"]

#: Mapping used for a folder of tables when none is given.
DEFAULT_MAPPING = "biotac_slide_20_50"
#: Mapping of bags when none is given: class from the bag's folder, trials numbered in order.
BAG_MAPPING = {"format": "bag", "class": {"from": "folder"}, "trial": {"from": "order"}}
_DIGITS = re.compile(r"^\d+$")


@dataclass
class LoadReport:
    """What reading a source found: trials, classes, and which trials were tared."""

    source: str
    mapping: str
    tared: list[tuple[str, int, float]] = field(default_factory=list)
    untared_detected: bool = False
    cell_type: str = "biotac"
    notes: list[str] = field(default_factory=list)

    def note_lines(self) -> list[str]:
        """Warnings about what was read (classes holding different trials, ...), one line each."""
        return list(self.notes)

    def tare_lines(self) -> list[str]:
        if not self.tared:
            return []
        levels = [lvl for _, _, lvl in self.tared]
        if self.cell_type != "biotac":
            why = "resting force at or above F_t: untared" if self.untared_detected else "tare: per_trial"
            return [f"tared {len(self.tared)} trials per trial ({why}; resting force {min(levels):.0f}.."
                    f"{max(levels):.0f} counts; each force channel loses its resting median)"]
        why = "resting PDC far from zero: untared" if self.untared_detected else "tare: per_trial"
        return [f"tared {len(self.tared)} trials per trial ({why}; PDC rest {min(levels):.0f}..{max(levels):.0f} "
                f"counts subtracted, electrodes by their resting medians)"]


def resolve_mapping(source: Path, mapping: str | Path | Mapping | None) -> Mapping:
    """The mapping to read ``source`` with (a bag's default, or :data:`DEFAULT_MAPPING`)."""
    if isinstance(mapping, Mapping):
        return mapping
    if mapping is not None:
        return load_mapping(mapping)
    if is_bag(source) or (source.is_dir() and any(is_bag(p) for pattern in ("*", "*/*") for p in source.glob(pattern))):
        return parse_mapping(BAG_MAPPING, source="<bag default>")
    return load_mapping(DEFAULT_MAPPING)


def format_numbers(values: Sequence[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3,5"``."""
    v = sorted(set(int(x) for x in values))
    if not v:
        return "none"
    parts, start, prev = [], v[0], v[0]
    for x in v[1:] + [None]:
        if x is not None and x == prev + 1:
            prev = x
            continue
        parts.append(f"{start}-{prev}" if prev > start else f"{start}")
        if x is not None:
            start = prev = x
    return ",".join(parts)


def check_selection(recordings: Sequence[BiotacRecording], trials: Sequence[int] | None,
                    classes: Sequence[str] | None, where: str,
                    unread_trials: Sequence[int] = (), unread_classes: Sequence[str] = ()
                    ) -> list[BiotacRecording]:
    """Keep the selected trials and classes; selecting what the data do not hold is an error.

    ``classes`` entries match a class name or its number; ``unread_trials``
    are trials the source holds that were skipped unread (they are named
    among what exists).

    Raises
    ------
    ConfigError
        Naming the trials or classes asked for but absent, and what exists.
    """
    out = list(recordings)
    if classes is not None:
        want = [str(c) for c in classes]
        have_names = {r.class_name for r in out} | {str(r.material) for r in out}
        absent = [c for c in want if c not in have_names]
        if absent:
            names = {f"{r.material} {r.class_name}" if str(r.material) != r.class_name else r.class_name
                     for r in out} | set(unread_classes)
            raise ConfigError(f"{where}: no class {', '.join(absent)}; the data hold "
                              + ", ".join(sorted(names, key=lambda x: (len(x.split()[0]), x))), key="materials")
        out = [r for r in out if r.class_name in want or str(r.material) in want]
    if trials is not None:
        have = {r.trial for r in out}
        absent = sorted(set(int(t) for t in trials) - have)
        if absent:
            raise ConfigError(f"{where}: no trial {format_numbers(absent)}; the data hold trials "
                              f"{format_numbers(sorted(have | set(unread_trials)))}", key="trials")
        out = [r for r in out if r.trial in set(trials)]
    if not out:
        raise ConfigError(f"{where}: the selection holds no recordings")
    return out


def _value(rule: NameRule, unit_names: dict[str, str], what: str, where: str) -> str | None:
    if rule.source == "option":
        return rule.value
    if rule.source in ("folder", "file", "group"):
        return rule.extract(unit_names[rule.source], what, where)
    return None  # column, order, message: later


def _names(unit: Unit, rules: Sequence[NameRule]) -> dict[str, str]:
    return {r.source: unit.name_of(r.source, "class") for r in rules if r.source in ("folder", "file", "group")}


@dataclass
class _Trial:
    class_value: str
    trial_value: str | None
    order_key: str
    frames: dict
    where: str
    source_file: str


def _table_trials(unit: Unit, mapping: Mapping, class_value: str | None, trial_value: str | None) -> list[_Trial]:
    table = read_table(unit, mapping.format, mapping)
    if table.n_rows == 0:
        raise DataFormatError(f"{unit.path}: no frames")
    cr, tr = mapping.class_rule, mapping.trial_rule
    keys, key_names = [], []
    for rule, what in ((cr, "class"), (tr, "trial")):
        if rule.source == "column":
            col = table.column(rule.column, f"{what}.column")
            keys.append(np.asarray(col).astype(str))
            key_names.append(what)
    runs = list(split_runs(keys)) if keys else [np.arange(table.n_rows)]
    out = []
    for sel in runs:
        sub = table.rows(sel) if keys else table
        cv, tv = class_value, trial_value
        for what, k in zip(key_names, keys):
            raw = str(k[sel[0]])
            rule = cr if what == "class" else tr
            v = rule.extract(raw, what, unit.path) if rule.pattern is not None else raw
            if what == "class":
                cv = v
            else:
                tv = v
        ch = table_channels(sub, mapping) if mapping.cell is None else cell_channels(sub, mapping)
        ch["frame_t_ns"] = frame_stamps_ns(sub, mapping, sub.n_rows)
        where = unit.path if not keys else f"{unit.path} rows {int(sel[0]) + 2}..{int(sel[-1]) + 2}"
        out.append(_Trial(str(cv), tv, f"{unit.path}:{int(sel[0]):09d}", ch, where, str(unit.file)))
    return out


def read_source(source: str | Path, mapping: str | Path | Mapping | None = None, *,
                trials: Sequence[int] | None = None, classes: Sequence[str] | None = None,
                class_name: str | None = None, tare: str | None = None,
                report: LoadReport | None = None) -> list[BiotacRecording]:
    """Read every trial of ``source`` as recordings, sorted by class number then trial.

    Parameters
    ----------
    source : path
        A folder of tables or bags, one table file, or one bag.
    mapping : str, path or Mapping, optional
        A shipped mapping's name, a mapping file, or a parsed mapping
        (default: :data:`BAG_MAPPING` for bags, else :data:`DEFAULT_MAPPING`).
    trials : sequence of int, optional
        Trials to keep (default all); absent ones are an error.
    classes : sequence of str, optional
        Classes to keep, by name or number (default all); absent ones are an error.
    class_name : str, optional
        Class of every trial (overrides the mapping's class rule).
    tare : {"auto", "per_trial", "none"}, optional
        Overrides the mapping's ``tare``.
    report : LoadReport, optional
        Filled with what was tared.

    Raises
    ------
    DataFormatError
        For a file that does not hold what the mapping says (the column or key is named).
    ConfigError
        For a bad mapping or a selection the data do not hold.
    """
    src = Path(source)
    m = resolve_mapping(src, mapping)
    if class_name is not None:
        m = replace(m, class_rule=NameRule(source="option", value=str(class_name)))
    tare_mode = tare or m.tare
    if report is not None:
        report.mapping = m.source
        report.cell_type = m.cell_type
    rules = [m.class_rule, m.trial_rule]
    raw: list[_Trial] = []
    unread: list[int] = []
    unread_classes: list[str] = []
    selected: set[str] = set()  # class values and names of the selected classes met
    if m.format == "bag":
        for bag in find_bags(src, None if m.files == "**/*" else m.files):
            unit = Unit(bag)
            names = _names(unit, rules)
            cv = _value(m.class_rule, names, "class", str(bag))
            tv = _value(m.trial_rule, names, "trial", str(bag))
            for i, fr in enumerate(read_bag_frames(bag, sensor=m.sensor, topic=m.topic)):
                # A bag that labels its frames (this package's) names its classes and trials itself;
                # only an explicit option overrides its class.
                c = fr["label"] if fr["label"] is not None and m.class_rule.source != "option" else cv
                if c is None:
                    raise ConfigError(f"{bag}: the bag names no class: give one (--class or mapping key class)",
                                      key="class")
                t = str(fr["trial"]) if fr["trial"] is not None else (tv if fr["label"] is None else None)
                raw.append(_Trial(str(c), t, f"{bag}:{i:09d}", fr, fr["where"], str(bag)))
    else:
        for unit in find_units(src, m):
            names = _names(unit, rules)
            cv = _value(m.class_rule, names, "class", unit.path)
            tv = _value(m.trial_rule, names, "trial", unit.path)
            if classes is not None and cv is not None and m.class_rule.source != "column":
                label = m.class_rule.names.get(cv, cv)
                if cv not in classes and label not in classes:
                    unread_classes.append(f"{cv} {label}" if cv != label else cv)
                    continue  # not selected: not even read (absent selections are checked below)
            if cv is not None:
                selected.update((cv, m.class_rule.names.get(cv, cv)))
            if trials is not None and tv is not None and _DIGITS.match(tv) and int(tv) not in trials:
                unread.append(int(tv))
                continue
            raw.extend(_table_trials(unit, m, cv, tv))
    if not raw:
        where = str(src)
        seen = {part for c in unread_classes for part in c.split(" ", 1)} | selected
        if classes is not None and any(c not in seen for c in classes):
            raise ConfigError(f"{where}: no class {', '.join(classes)}; the data hold "
                              + ", ".join(sorted(set(unread_classes), key=lambda x: (len(x.split()[0]), x))),
                              key="materials")
        if trials is not None and unread:
            raise ConfigError(f"{where}: no trial {format_numbers(trials)}; the data hold trials "
                              f"{format_numbers(unread)}", key="trials")
        raise DataFormatError(f"{where}: no trials found")
    recs = _build(raw, m, tare_mode, report)
    return check_selection(recs, trials, classes, str(src), unread, sorted(set(unread_classes)))


def _number_map(values: Sequence[str]) -> dict[str, int]:
    uniq = sorted(set(values), key=natural_key)
    if all(_DIGITS.match(v) for v in uniq):
        return {v: int(v) for v in uniq}
    return {v: i + 1 for i, v in enumerate(uniq)}


def _build(raw: list[_Trial], m: Mapping, tare_mode: str, report: LoadReport | None) -> list[BiotacRecording]:
    cnum = _number_map([t.class_value for t in raw])
    by_class: dict[str, list[_Trial]] = {}
    for t in raw:
        by_class.setdefault(t.class_value, []).append(t)
    recs = []
    for cv, ts in by_class.items():
        ts.sort(key=lambda t: natural_key(t.order_key))
        if all(t.trial_value is not None for t in ts):
            tnum = _number_map([t.trial_value for t in ts])
            numbers = [tnum[t.trial_value] for t in ts]
        else:
            numbers = list(range(1, len(ts) + 1))
        if len(set(numbers)) != len(numbers):
            dup = sorted({n for n in numbers if numbers.count(n) > 1})
            both = [t.where for t, n in zip(ts, numbers) if n == dup[0]]
            raise DataFormatError(f"{m.source}: class {cv}: trial {dup[0]} twice ({' and '.join(both)}; mapping key "
                                  f"trial, {_rule_text(m.trial_rule)}): the trial rule must tell trials apart, "
                                  "e.g. trial.number over several groups of trial.pattern")
        name = m.class_rule.names.get(cv, cv)
        if _DIGITS.match(name):
            name = f"mat{name}"
        for t, num in zip(ts, numbers):
            recs.append(_recording(t, cnum[cv], num, name, m))
    recs.sort(key=lambda r: (r.material, r.trial))
    if report is not None:
        report.notes.extend(trial_set_notes(recs))
    if m.cell is not None:
        return [_tare_cell(r, m, tare_mode, report) for r in recs]
    out = []
    for r in recs:
        if tare_mode == "none":
            out.append(r)
            continue
        rest = trial_rest(r)
        if tare_mode == "per_trial" or rest.reference[0] > UNTARED_REST_COUNTS:
            r = tare_recording(r, rest)
            if report is not None:
                report.tared.append((r.class_name, r.trial, r.tare_counts[0]))
                report.untared_detected |= tare_mode == "auto"
        out.append(r)
    return out


def _rule_text(rule: NameRule) -> str:
    parts = [f"from {rule.source}"]
    if rule.pattern is not None:
        parts.append(f"pattern {rule.pattern.pattern!r}")
    if rule.number is not None:
        parts.append(f"number {rule.number!r}")
    return ", ".join(parts)


def trial_set_notes(recs: Sequence[BiotacRecording]) -> list[str]:
    """One warning line when the classes do not hold the same trial numbers (a missing run, or runs
    numbered differently per class): a split by trial then tests the classes on different runs.

    The line names each class whose trials differ from those most classes hold, and how.
    """
    sets: dict[str, set[int]] = {}
    for r in recs:
        sets.setdefault(r.class_name, set()).add(r.trial)
    kinds = [frozenset(v) for v in sets.values()]
    if len(set(kinds)) <= 1:
        return []
    usual = max(set(kinds), key=lambda k: (kinds.count(k), len(k)))
    odd = []
    for c, v in sets.items():
        if v == usual:
            continue
        how = []
        if usual - v:
            how.append(f"lacks {format_numbers(sorted(usual - v))}")
        if v - usual:
            how.append(f"also holds {format_numbers(sorted(v - usual))}")
        odd.append(f"{c} {' and '.join(how)}")
    return [f"classes hold different trials: {'; '.join(odd[:6])}"
            + (f"; ... {len(odd)} classes in all" if len(odd) > 6 else "")
            + f" (the other classes hold {format_numbers(sorted(usual))}): a split by trial number tests "
              "them on different runs"]


def _recording(t: _Trial, material: int, trial: int, name: str, m: Mapping) -> BiotacRecording | CellRecording:
    fr = t.frames
    if m.cell is not None:
        return _cell_recording(t, material, trial, name, m)
    pac2 = np.asarray(fr["pac"], dtype=np.int64)
    k = int(pac2.shape[1])
    frame_t = np.asarray(fr["frame_t_ns"], dtype=np.int64)
    pac_t = fr.get("pac_t_ns")
    pac_t = spread_pac_stamps(frame_t, k, t.where) if pac_t is None else np.asarray(pac_t, dtype=np.int64)
    if pac_t.shape[0] > 1 and np.any(np.diff(pac_t) <= 0):
        raise DataFormatError(f"{t.where}: PAC sample times do not increase")
    return BiotacRecording(material=material, trial=trial, frame_t_ns=frame_t, pac=pac2.ravel(), pac_t_ns=pac_t,
                           pdc=np.asarray(fr["pdc"], dtype=np.int64), tac=np.asarray(fr["tac"], dtype=np.int64),
                           tdc=np.asarray(fr["tdc"], dtype=np.int64),
                           electrodes=np.asarray(fr["electrodes"], dtype=np.int64), path=t.where,
                           class_name=name, pac_per_frame=k, source_file=t.source_file,
                           absent=tuple(fr.get("absent", ())))


def _cell_recording(t: _Trial, material: int, trial: int, name: str, m: Mapping) -> CellRecording:
    fr, ct = t.frames, m.cell
    assert ct is not None
    frame_t = np.asarray(fr["frame_t_ns"], dtype=np.int64)
    k = m.samples_per_frame
    vib_t = spread_pac_stamps(frame_t, k, t.where)
    dfm, extra = fr["deformation"], fr["extra"]
    force = _force_channels(ct, dfm, extra).mean(axis=0)
    return CellRecording(material=material, trial=trial, frame_t_ns=frame_t, vibration=fr["vibration"],
                         vibration_t_ns=vib_t, deformation=dfm, extra=extra, force_counts=force,
                         deformation_tare=np.zeros(dfm.shape[0]), path=t.where, robot=m.robot, cell_type=ct.name,
                         class_name=name, samples_per_frame=k, source_file=t.source_file, absent=fr["absent"])


def _force_channels(ct, deformation: np.ndarray, extra: np.ndarray) -> np.ndarray:
    """The force channels' values (n_force, n_frames), from the deformation or the extra channels."""
    rows = []
    for c in ct.force.channels:
        if c in ct.deformation.channels:
            rows.append(deformation[ct.deformation.channels.index(c)].astype(np.float64))
        else:
            rows.append(np.asarray(extra[ct.extra_channels.index(c)], dtype=np.float64))
    return np.stack(rows)


def _tare_cell(r: CellRecording, m: Mapping, tare_mode: str, report: LoadReport | None) -> CellRecording:
    """Tare a cell's force channels when its resting force is not near zero (``tare: auto``) or always.

    The force channels' resting level is
    :func:`~tactile_descriptors_ros.core.tare.resting_level` over the trial
    (its frames whose mean force lies at or below the
    :data:`~tactile_descriptors_ros.core.tare.TRIAL_REST_PERCENTILE` th
    percentile; each channel's median over them), as a driver's ``~/tare``
    takes it over its window.  A trial whose resting mean force is at or
    above F_t of the cell type's robot (the contact gate would pass every
    frame) is untared.  The counts stay as recorded, the tare goes to
    ``deformation_tare`` (subtracted by the ``levels`` group, as a driver's
    reported tare) and to the force.
    """
    from tactile_descriptors_ros.core.robot import load_robot

    if tare_mode == "none":
        return r
    ct = m.cell
    assert ct is not None
    robot = load_robot(m.robot)
    npc = ct.force.n_per_count
    if not np.isfinite(r.force_counts).any():
        raise DataFormatError(f"{r.path}: the force channels {', '.join(ct.force.channels)} hold no value")
    forces = _force_channels(ct, r.deformation, r.extra)
    try:
        rest = resting_level(forces, rest_percentile=TRIAL_REST_PERCENTILE)
    except SignalError as e:
        raise DataFormatError(f"{r.path}: no resting force level: {e}") from None
    tare = rest.reference
    level = float(tare.mean())
    if tare_mode == "auto" and level * npc < robot.contact.force_threshold_n:
        return r
    d_tare = np.zeros(r.deformation.shape[0])
    for c, v in zip(ct.force.channels, tare):
        if c in ct.deformation.channels:
            d_tare[ct.deformation.channels.index(c)] = v
    if report is not None:
        report.tared.append((r.class_name, r.trial, level))
        report.untared_detected |= tare_mode == "auto"
    return replace(r, force_counts=(forces - tare[:, None]).mean(axis=0), deformation_tare=d_tare,
                   tare_counts=tuple(float(v) for v in tare))


def align_classes(*splits: Sequence[BiotacRecording]) -> list[list[BiotacRecording]]:
    """Give every class the same number in all splits (by class name), when the splits disagree.

    Two sources that name classes by words number them by their own sorted
    names; evaluation compares numbers, so they are made to agree.
    """
    pairs = {(r.material, r.class_name) for s in splits for r in s}
    by_num: dict[int, set[str]] = {}
    by_name: dict[str, set[int]] = {}
    for n, c in pairs:
        by_num.setdefault(n, set()).add(c)
        by_name.setdefault(c, set()).add(n)
    if all(len(v) == 1 for v in by_num.values()) and all(len(v) == 1 for v in by_name.values()):
        return [list(s) for s in splits]
    number = {c: i + 1 for i, c in enumerate(sorted(by_name))}
    return [[replace(r, material=number[r.class_name]) for r in s] for s in splits]
