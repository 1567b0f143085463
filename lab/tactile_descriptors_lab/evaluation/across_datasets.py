"""The default descriptor against plain statistics on every data set the docs show, by trial cross-validation.

A descriptor that helps on one data set can fall below the plainest one on
another.  This runs the same protocol on each layout the readers take:

* **shared BioTac**: the shared recordings as they are (the report's
  ``trial_cv`` section scores the same two modes; here the selection too);
* **Penn BOLT layout**: five of the shared materials written as a PR2
  gripper's runs (:func:`~..datasets.layouts.write_penn_bolt`): 3 sessions of
  5 runs an object, one run missing (74 runs, as the published set), finger 0
  read through its mapping; a fold is a session;
* **iCub taxel pad**: a pressure-only pad of 60 taxels at 50 Hz built from
  every shared trial (:func:`~..datasets.layouts.write_icub_split`), float
  ``.npy`` arrays and their class names read through its mapping;
* **simulated NAO**: one right-hand skin cell of the NAO simulator sliding
  over the 20 fitted materials at a controlled force and speed (the paper's
  NAO protocol), written as HDF5 tables.

For each: cross-validation over contiguous blocks of trials (each block the
test set once, :func:`~.experiments.trial_cv`), ``plain`` (mean, sd, min and
max of every channel) against the evaluation's default mode less the groups
the cell type cannot feed (:func:`~.bank.fed_mode`: what ``tactile
evaluate`` runs without ``--mode``), with the same classifiers, windows and
seeds; and the choice between the two made inside each fold's training
trials (``tactile evaluate --select plain,<default>``), which is how a
selection stays at or above plain statistics where the default does not.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from tactile_descriptors_lab.datasets.layouts import (
    PENN_OBJECTS,
    icub_mapping,
    icub_robot_yaml,
    penn_bolt_mapping,
    simulated_skin_trials,
    skin_hdf5_mapping,
    write_icub_split,
    write_penn_bolt,
    write_skin_hdf5,
)
from tactile_descriptors_lab.datasets.readers import read_source
from tactile_descriptors_lab.datasets.recording import BiotacRecording
from tactile_descriptors_lab.evaluation.bank import fed_mode, recordings_cell_type
from tactile_descriptors_lab.evaluation.experiments import EvalConfig, selected_trial_cv, trial_cv

__all__ = ["DatasetPlan", "FULL_DATASETS", "QUICK_DATASETS", "FLOOR_MODE", "write_sources", "evaluate_datasets",
           "default_at_least_floor"]

#: The floor every data set's default descriptor is compared with.
FLOOR_MODE: str = "plain"


@dataclass(frozen=True)
class DatasetPlan:
    """What :func:`evaluate_datasets` builds and runs.

    Attributes
    ----------
    trials : int
        Trials of each shared material used (1..trials): the Penn objects'
        runs (two trials a run, one a finger) and the iCub pad's trials.
    penn_runs_per_session : int
        Runs of a Penn session (sessions = trials / 2 / runs).
    penn_skip : tuple of (str, int, int)
        Runs left out, ``(object, session, run)``.
    icub_materials : int or None
        The first ``icub_materials`` shared materials on the pad (None: all).
    icub_rate_hz : float
        The pad's frame rate (every other BioTac frame: 50 Hz).
    nao_materials : int or None
        The first fitted materials the simulated NAO touches (None: all 20).
    nao_repeat : int
        Touches a material.
    nao_force_n, nao_speed_m_s, nao_duration_s : float
        The controlled force, speed and sliding time of a touch.
    window : str
        Training and test window of every data set.
    folds : int
        Blocks of trials of the cross-validation.
    train_per_trial : int or None
        Training windows a trial (None: the configuration's).
    """

    trials: int = 30
    penn_runs_per_session: int = 5
    penn_skip: tuple[tuple[str, int, int], ...] = (("felt_pad", 3, 5),)
    icub_materials: int | None = None
    icub_rate_hz: float = 50.0
    nao_materials: int | None = None
    nao_repeat: int = 9
    nao_force_n: float = 1.4
    nao_speed_m_s: float = 0.02
    nao_duration_s: float = 2.5
    window: str = "2"
    folds: int = 3
    train_per_trial: int | None = None


#: The report's plan.
FULL_DATASETS = DatasetPlan()
#: A plan for tests: few trials and materials, 1 s windows.
QUICK_DATASETS = DatasetPlan(trials=12, penn_runs_per_session=2, penn_skip=(), icub_materials=4, nao_materials=3,
                             nao_repeat=6, nao_duration_s=1.5, window="1", folds=3, train_per_trial=3)


def _write_yaml(path: Path, data: dict) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def write_sources(recs: Sequence[BiotacRecording], folder: str | Path, plan: DatasetPlan = FULL_DATASETS
                  ) -> dict[str, dict]:
    """Write the Penn, iCub and NAO data sets into ``folder``, each beside its mapping.

    Parameters
    ----------
    recs : sequence of BiotacRecording
        The shared recordings (trials 1..``plan.trials`` of the materials used).

    Returns
    -------
    dict
        By data set name: ``source`` (the path ``tactile evaluate --train`` takes), ``mapping`` (its
        ``--mapping``) and ``about`` (one line: what the layout holds).
    """
    folder = Path(folder)
    names = {r.material: r.class_name for r in recs}
    mats = sorted(names)
    used = [r for r in recs if r.trial <= plan.trials]
    out: dict[str, dict] = {}

    penn = folder / "penn"
    penn.mkdir(parents=True, exist_ok=True)
    # the five named objects where the recordings hold them, else the first five materials by their names
    objects = PENN_OBJECTS if set(PENN_OBJECTS) <= set(mats) else {m: names[m] for m in mats[:len(PENN_OBJECTS)]}
    runs = write_penn_bolt(penn / "bolt.h5", [r for r in used if r.material in objects], objects,
                           plan.penn_runs_per_session, skip=plan.penn_skip)
    out["Penn BOLT layout"] = {
        "source": penn, "mapping": _write_yaml(folder / "penn.yaml", penn_bolt_mapping(0)),
        "about": f"{len(objects)} objects, {len(runs)} runs of a PR2 gripper's two BioTacs (HDF5, finger 0 "
                 "read), built from the shared recordings"}

    icub = folder / "icub"
    icub.mkdir(parents=True, exist_ok=True)
    pad_mats = mats if plan.icub_materials is None else mats[:plan.icub_materials]
    pad = [r for r in used if r.material in pad_mats]
    frames = min(r.n_frames for r in pad) // 2
    # trial-major: the trial axis numbers rows 1, 2, ...; contiguous blocks of them are blocks of trials
    pad.sort(key=lambda r: (r.trial, r.material))
    (icub / "icub_pad.yaml").write_text(icub_robot_yaml(plan.icub_rate_hz))
    write_icub_split(icub, "all", pad, names, frames)
    out["iCub taxel pad"] = {
        "source": icub / "X_all.npy",
        "mapping": _write_yaml(icub / "icub.yaml", icub_mapping("icub_pad.yaml", plan.icub_rate_hz)),
        "about": f"{len(pad_mats)} materials, {len(pad)} trials of a 60-taxel pressure-only pad at "
                 f"{plan.icub_rate_hz:g} Hz (float .npy arrays), built from the shared recordings' electrodes"}

    from tactile_descriptors_ros.sim.textures import material_library

    fitted = sorted(material_library())
    nao_mats = fitted if plan.nao_materials is None else fitted[:plan.nao_materials]
    trials = simulated_skin_trials(nao_mats, repeat=plan.nao_repeat, seed=11, force_n=plan.nao_force_n,
                                   speed_m_s=plan.nao_speed_m_s, duration_s=plan.nao_duration_s, order="shuffled")
    nao = folder / "nao"
    nao.mkdir(parents=True, exist_ok=True)
    write_skin_hdf5(nao / "skin.h5", trials)
    out["simulated NAO"] = {
        "source": nao, "mapping": _write_yaml(folder / "nao.yaml", skin_hdf5_mapping()),
        "about": f"{len(nao_mats)} fitted materials x {plan.nao_repeat} lateral slides of a NAO right-hand skin "
                 f"cell at {plan.nao_force_n:g} N and {100 * plan.nao_speed_m_s:g} cm/s (simulator, HDF5 tables)"}
    return out


def evaluate_datasets(recs: Sequence[BiotacRecording], folder: str | Path, cfg: EvalConfig,
                      plan: DatasetPlan = FULL_DATASETS, progress=None) -> dict[str, dict]:
    """Write the data sets (:func:`write_sources`), read each back through its mapping, and score
    :data:`FLOOR_MODE` and the default mode by trial cross-validation.

    Parameters
    ----------
    cfg : EvalConfig
        Classifiers, seeds and scaling; its ``window`` and ``mode`` are set per data set.
    progress : callable, optional
        Called with a short text before each evaluation.

    Returns
    -------
    dict
        By data set name (``shared BioTac`` first: ``recs`` as given): ``about``, ``source`` and ``mapping``
        (file names; empty for the shared recordings), ``classes``, ``trials``,
        ``window``, ``mode`` (the default mode run), ``left_out`` (its groups the cell type cannot feed),
        ``cv`` by mode (:func:`~.experiments.trial_cv`'s summary) and ``selected``: the two chosen between
        inside each fold's training trials (:func:`~.experiments.selected_trial_cv`), what ``tactile evaluate
        --select plain,<default>`` scores.
    """
    out: dict[str, dict] = {}
    used = [r for r in recs if r.trial <= plan.trials]
    trials = sorted({r.trial for r in used})
    sets = {"shared BioTac": {"records": used, "source": "", "mapping": "",
                              "about": f"the shared recordings, {len({r.material for r in used})} materials, trials "
                                       f"{trials[0]}-{trials[-1]} (CSV)"}}
    for name, src in write_sources(recs, folder, plan).items():
        sets[name] = {**src, "records": read_source(src["source"], src["mapping"])}
    run = replace(cfg, window=plan.window,
                  train_per_trial=cfg.train_per_trial if plan.train_per_trial is None else plan.train_per_trial)
    for name, src in sets.items():
        records = src["records"]
        mode, left, _ = fed_mode(recordings_cell_type(records))
        row = {"about": src["about"], "source": Path(src["source"]).name, "mapping": Path(src["mapping"]).name,
               "classes": len({r.class_name for r in records}), "trials": len(records),
               "window": plan.window, "mode": mode, "left_out": list(left), "cv": {}}
        for m in (FLOOR_MODE, mode):
            if progress is not None:
                progress(f"{name}: {m}")
            row["cv"][m] = trial_cv(records, replace(run, mode=m), plan.folds)
        if progress is not None:
            progress(f"{name}: selection")
        row["selected"] = selected_trial_cv(records, run, (FLOOR_MODE, mode), plan.folds)
        out[name] = row
    return out


def default_at_least_floor(row: dict, classifier: str) -> bool:
    """True when the default mode's mean accuracy is at least :data:`FLOOR_MODE`'s for ``classifier``."""
    acc = {m: row["cv"][m]["classifiers"][classifier]["accuracy"] for m in (FLOOR_MODE, row["mode"])}
    return bool(np.round(acc[row["mode"]], 6) >= np.round(acc[FLOOR_MODE], 6))
