"""Other labs' recording layouts, built from recordings this package reads.

The readers take other labs' files as published (``tactile import`` and
``tactile evaluate`` with a mapping); these writers build the closest layout
that can be made from the data at hand, so that the readers, and what a
descriptor scores through them, can be checked without the original files:

* the Penn BOLT layout (:func:`write_penn_bolt`): an HDF5 file of a PR2
  gripper's runs, two BioTacs below each run, stamps in the parent group;
* the iCub taxel pads' arrays (:func:`write_icub_split`): float ``.npy``
  arrays of a pressure-only cell type and their class names;
* BioTac frames as ``.npy`` arrays (:func:`write_npy_split`);
* a NAO skin cell's trials from the simulator (:func:`simulated_skin_trials`),
  as HDF5 tables (:func:`write_skin_hdf5`).

Each writer has its mapping beside it (``*_mapping``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.recording import BiotacRecording
from tactile_descriptors_ros.errors import ConfigError

#: A skin cell's accelerometer samples a force sample (1 kHz / 250 Hz, config/nao.yaml).
SKIN_SAMPLES_PER_FRAME = 4


#: The simulator's effects of :func:`simulated_skin_trials` (``config/scenes`` syntax).
SKIN_TRIAL_EFFECTS: dict = {"normal_force": {"ramp_s": 0.1}, "texture_vibration": {}, "proximity": {},
                            "sensor_noise": {"std_counts": 1.0}, "adc": {}}


def simulated_skin_trials(materials=("cork", "steel"), repeat: int = 2, seed: int = 3, *, force_n: float = 2.0,
                          speed_m_s: float = 0.03, duration_s: float = 2.0, order: str = "round_robin",
                          effects: dict | None = None, cell: int = 15) -> list[dict]:
    """Skin trials from the simulator: one NAO right-hand cell sliding over each material.

    The right hand slides laterally ``repeat`` times over each material at a
    controlled force and speed (the paper's NAO protocol, Sec. V-A1), for
    ``duration_s`` seconds a touch, in the scene's ``order`` (``round_robin``,
    ``shuffled`` or ``blocked``).

    Returns
    -------
    list of dict
        One a touch, in the scene's order: ``class_name``, ``trial`` (1, 2, ...
        per material), ``t_ns`` (force sample stamps, one a frame),
        ``vibration`` (3, n * 4: ax, ay, az counts, the 4 accelerometer samples
        of each frame), ``force`` (3, n: f1 f2 f3 counts), ``proximity`` (n,)
        and ``temperature`` (n,, degC), from 0.3 s before the touch to 0.3 s
        after the release.
    """
    from tactile_descriptors_ros.sim import parse_scene, simulate
    from tactile_descriptors_ros.sim.scene import restrict_robot

    scene = {"scene": {"name": "skin_tables", "robot": "nao", "seed": seed, "lead_in_s": 0.5},
             "effects": dict(SKIN_TRIAL_EFFECTS if effects is None else effects),
             "explorations": [{"materials": list(materials), "repeat": repeat, "order": order,
                               "body_parts": ["right_hand"], "motion": "lateral", "force_n": force_n,
                               "speed_m_s": speed_m_s, "duration_s": duration_s, "pause_s": 0.8}]}
    res = simulate(restrict_robot(parse_scene(scene), ["right_hand"]))
    streams = res.cells[cell].streams
    acc, frc = streams["accel"], streams["force"]
    prox, temp = streams["proximity"], streams["temperature"]
    k = SKIN_SAMPLES_PER_FRAME
    if acc.t_ns[0] != frc.t_ns[0] or acc.rate_hz != k * frc.rate_hz:
        raise ConfigError(f"cell {cell}: accelerometer at {acc.rate_hz:g} Hz from {acc.t_ns[0]} ns, force at "
                          f"{frc.rate_hz:g} Hz from {frc.t_ns[0]} ns: the tables need {k} accelerometer samples "
                          "a force sample, from one start", key="cell")
    trials, seen = [], {}
    for e in res.explorations:
        name = e.exploration.material
        seen[name] = seen.get(name, 0) + 1
        a, b = np.searchsorted(frc.t_ns, [e.onset_ns - 300_000_000, e.release_ns + 300_000_000])
        t = frc.t_ns[a:b]
        held = np.searchsorted(temp.t_ns, t, side="right") - 1
        trials.append({"class_name": name, "trial": seen[name], "t_ns": t.astype(np.int64),
                       "vibration": acc.counts[:, a * k:b * k].astype(np.int64),
                       "force": frc.counts[:, a:b].astype(np.int64),
                       "proximity": prox.counts[0, a:b].astype(np.float64),
                       "temperature": temp.counts[0, held].astype(np.float64) / 100.0})
    return trials


def skin_columns(tr: dict) -> dict[str, np.ndarray]:
    k = SKIN_SAMPLES_PER_FRAME
    cols = {"t_ns": tr["t_ns"]}
    for row, axis in enumerate("xyz"):
        frames = tr["vibration"][row].reshape(-1, k)
        for i in range(k):
            cols[f"acc_{axis}{i + 1}"] = frames[:, i]
    for j in range(3):
        cols[f"force{j + 1}"] = tr["force"][j]
    cols["prox"], cols["temp_c"] = tr["proximity"], tr["temperature"]
    return cols


def write_skin_hdf5(path: Path, trials: list[dict]) -> Path:
    """One HDF5 file, a group ``<class>/trial_<n>`` a trial, a dataset a column."""
    import h5py

    with h5py.File(path, "w") as h5:
        for tr in trials:
            g = h5.create_group(f"{tr['class_name']}/trial_{tr['trial']}")
            for name, values in skin_columns(tr).items():
                g[name] = values
    return path


#: The channels of :func:`skin_columns` for a NAO skin cell (mapping ``channels``).
SKIN_CHANNELS: dict = {"ax": "acc_x{i}", "ay": "acc_y{i}", "az": "acc_z{i}", "f1": "force1", "f2": "force2",
                       "f3": "force3", "proximity": "prox", "temperature": "temp_c"}


def skin_hdf5_mapping() -> dict:
    """The mapping of :func:`write_skin_hdf5`'s file: NAO skin cells, a group ``<class>/trial_<n>`` a trial."""
    return {"format": "hdf5", "files": "*.h5", "groups": "*/trial_*", "robot": "nao", "cell_type": "skin_cell",
            "class": {"from": "group", "pattern": "^([^/]+)/"}, "trial": {"from": "group", "pattern": r"trial_(\d+)$"},
            "samples_per_frame": SKIN_SAMPLES_PER_FRAME, "channels": dict(SKIN_CHANNELS),
            "stamps": {"column": "t_ns", "unit": "ns"}, "tare": "none"}


# --------------------------------------------------------------------------- other labs' layouts

#: Penn BOLT's objects in the built layout: five shared materials (class number -> object name).
PENN_OBJECTS = {2: "bouncy_foam", 5: "cork_board", 9: "felt_pad", 12: "cork", 17: "steel_plate"}


def penn_run_name(obj: str, session: int, run: int) -> str:
    """A run group's name: object, session and run (``cork_1_03``); a trial is session and run together."""
    return f"{obj}_{session}_{run:02d}"


def write_penn_bolt(path: Path, recs: list[BiotacRecording], names: dict[int, str], runs_per_session: int,
                    skip: tuple[tuple[str, int, int], ...] = ()) -> list[tuple[str, int, int]]:
    """One HDF5 file in the Penn BOLT layout, built from recordings of one BioTac.

    A group a run, named by :func:`penn_run_name`; below it a PR2 gripper's two BioTacs ``biotacs/finger_0``
    and ``biotacs/finger_1``, each with ``pac`` (frames, 22), ``electrodes`` (frames, 19), ``pdc``, ``tac``,
    ``tdc`` (uint16 counts as the sensor sends them), the frame stamps ``timestamps`` (float seconds) once
    in ``biotacs``, the parent group of the fingers, and a gripper aperture at its own rate (50 Hz) beside
    them, as the PR2 logs it.  Run ``r`` of session ``s`` holds trial ``(s - 1) * runs_per_session + r`` of
    the material on ``finger_0`` and the next trial of the same material on ``finger_1`` (both cut to the
    shorter); ``skip`` leaves out runs (``(object, session, run)``), as a data set with a missing run.

    Returns the ``(object, session, run)`` of every run written.
    """
    import h5py

    by = {(r.material, r.trial): r for r in recs}
    written = []
    with h5py.File(path, "w") as h5:
        for (mat, trial), r0 in sorted(by.items()):
            if (mat, trial + 1) not in by or (trial - 1) % 2:
                continue  # odd trials start a run, the next trial is its second finger
            run_index = (trial + 1) // 2
            session, run = (run_index - 1) // runs_per_session + 1, (run_index - 1) % runs_per_session + 1
            if (names[mat], session, run) in skip:
                continue
            r1 = by[(mat, trial + 1)]
            n = min(r0.n_frames, r1.n_frames)
            g = h5.create_group(penn_run_name(names[mat], session, run))
            bt = g.create_group("biotacs")
            bt["timestamps"] = (r0.frame_t_ns[:n] - r0.frame_t_ns[0]) * 1e-9 + 1_300_000_000.0 + 60.0 * run_index
            for f, r in enumerate((r0, r1)):
                fg = bt.create_group(f"finger_{f}")
                fg["pac"] = r.pac[:n * r.pac_per_frame].reshape(n, r.pac_per_frame).astype(np.uint16)
                fg["electrodes"] = r.electrodes[:, :n].T.astype(np.uint16)
                for ch in ("pdc", "tac", "tdc"):
                    fg[ch] = getattr(r, ch)[:n].astype(np.uint16)
            g.create_group("gripper")["aperture"] = np.linspace(0.08, 0.02, n // 2)
            written.append((names[mat], session, run))
    return written


def penn_bolt_mapping(finger: int = 0) -> dict:
    """The mapping of :func:`write_penn_bolt`'s layout: channels below the run group, classes by name, the
    trial number built from the session and the run."""
    f = f"biotacs/finger_{finger}"
    return {
        "format": "hdf5", "files": "*.h5", "groups": "*",
        "class": {"from": "group", "pattern": r"^(?P<class>.+)_\d+_\d+$"},
        "trial": {"from": "group", "pattern": r"_(\d+)_(\d+)$", "number": "{0}{1:02d}"},
        "channels": {"pac": f"{f}/pac", "pdc": f"{f}/pdc", "tac": f"{f}/tac", "tdc": f"{f}/tdc",
                     "electrodes": f"{f}/electrodes"},
        "stamps": {"column": "biotacs/timestamps", "unit": "s"},
    }


#: Columns of :func:`write_npy_split`'s arrays: PDC, TAC, TDC, the 19 electrodes, the 22 PAC samples a frame.
NPY_COLUMNS = ["pdc", "tac", "tdc", {"name": "e{i}", "count": 19}, {"name": "pac{i}", "count": 22}]


def write_npy_split(folder: Path, split: str, recs: list[BiotacRecording], names: dict[int, str], frames: int,
                    units_per_count: float) -> Path:
    """One split as the iCub pads' files are laid out: ``X_<split>.npy``, a float array (trials, columns,
    frames) of every trial's first ``frames`` frames in units (counts x ``units_per_count``), and
    ``y_<split>.npy``, the class name of each trial."""
    rows = []
    for r in recs:
        pac = r.pac[:frames * r.pac_per_frame].reshape(frames, r.pac_per_frame)
        cols = np.column_stack([r.pdc[:frames], r.tac[:frames], r.tdc[:frames], r.electrodes[:, :frames].T, pac])
        rows.append(cols.T.astype(np.float64) * units_per_count)
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / f"X_{split}.npy", np.stack(rows))
    np.save(folder / f"y_{split}.npy", np.array([names[r.material] for r in recs]))
    return folder / f"X_{split}.npy"


def npy_split_mapping(counts_per_unit: float) -> dict:
    """The mapping of :func:`write_npy_split`'s files."""
    return {"format": "npy", "files": "X_*.npy", "shape": ["trial", "column", "frame"], "columns": NPY_COLUMNS,
            "labels": {"replace": ["X_", "y_"]}, "class": {"from": "column", "column": "label"},
            "trial": {"from": "column", "column": "trial"}, "counts_per_unit": counts_per_unit,
            "channels": {"pac": "pac{i}", "pdc": "pdc", "tac": "tac", "tdc": "tdc", "electrodes": "e{i}"},
            "stamps": {"rate_hz": 100.0}, "tare": "none"}


# --------------------------------------------------------------------------- iCub taxel pads

#: Taxels of the built iCub pad: six triangular modules of ten.
ICUB_TAXELS = 60
#: Stored units per count of the pad's float values (1/1024: every count exact in a float).
ICUB_UNITS_PER_COUNT = 1 / 1024


def icub_robot_yaml(rate_hz: float = 50.0) -> str:
    """A robot description of one iCub taxel pad: a pressure-only cell type (no vibration section), its
    60 taxels the deformation channels, one axis per ten-taxel module, the force their mean."""
    modules = ", ".join("{name: m" + str(m + 1) + ", channels: [" + ", ".join(f"t{10 * m + i + 1}" for i in range(10))
                        + "]}" for m in range(ICUB_TAXELS // 10))
    taxels = ", ".join(f"t{i}" for i in range(1, ICUB_TAXELS + 1))
    return (f"robot: {{name: icub_pad, description: 'an iCub capacitive taxel pad, pressure only'}}\n"
            f"cell_types:\n  taxel_pad:\n"
            f"    deformation: {{symbol: P, rate_hz: {rate_hz}, adc_bits: 12, axes: [{modules}]}}\n"
            f"    force: {{channels: [{taxels}], n_per_count: 0.001, rate_hz: {rate_hz}}}\n"
            f"body_parts:\n  - {{name: palm, cell_type: taxel_pad, cells: [{{id: 1}}]}}\n")


def icub_taxel_counts(rec: BiotacRecording, frames: int, seed: int = 7) -> np.ndarray:
    """The pad's counts (frames at 50 Hz, 60) from a BioTac trial at 100 Hz: every other frame; taxel k a
    fixed mix of electrodes k and k + 1 (mod 19), as neighbouring taxels share a pressure; the last three
    taxels mixes of PDC and an electrode.  Integer counts (the pad's ADC)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(0.3, 0.9, ICUB_TAXELS)
    e = rec.electrodes[:, :2 * frames:2].astype(np.float64)
    pdc = rec.pdc[:2 * frames:2].astype(np.float64)
    out = np.empty((e.shape[1], ICUB_TAXELS))
    for k in range(ICUB_TAXELS - 3):
        out[:, k] = w[k] * e[k % 19] + (1 - w[k]) * e[(k + 1) % 19]
    for k in range(ICUB_TAXELS - 3, ICUB_TAXELS):
        out[:, k] = w[k] * pdc + (1 - w[k]) * e[k % 19]
    return np.round(out).astype(np.int64)


def write_icub_split(folder: Path, split: str, recs: list[BiotacRecording], names: dict[int, str],
                     frames: int) -> Path:
    """``X_<split>.npy``: float array (trials, frames, 60) of the pad's values in units
    (:data:`ICUB_UNITS_PER_COUNT` each), ``y_<split>.npy`` the class names, as the iCub data ship."""
    folder.mkdir(parents=True, exist_ok=True)
    x = np.stack([icub_taxel_counts(r, frames) for r in recs]).astype(np.float64) * ICUB_UNITS_PER_COUNT
    np.save(folder / f"X_{split}.npy", x)
    np.save(folder / f"y_{split}.npy", np.array([names[r.material] for r in recs]))
    return folder / f"X_{split}.npy"


def icub_mapping(robot_file: str = "icub_pad.yaml", rate_hz: float = 50.0) -> dict:
    """The mapping of :func:`write_icub_split`'s files and :func:`icub_robot_yaml`'s pad."""
    return {"format": "npy", "files": "X_*.npy", "shape": ["trial", "frame", "column"],
            "columns": [{"name": "t{i}", "count": ICUB_TAXELS}], "labels": {"replace": ["X_", "y_"]},
            "class": {"from": "column", "column": "label"}, "trial": {"from": "column", "column": "trial"},
            "robot": robot_file, "counts_per_unit": 1 / ICUB_UNITS_PER_COUNT,
            "channels": {f"t{i}": f"t{i}" for i in range(1, ICUB_TAXELS + 1)}, "stamps": {"rate_hz": rate_hz},
            "tare": "none"}
