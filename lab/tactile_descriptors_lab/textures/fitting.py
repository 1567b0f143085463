"""Texture models fitted to real BioTac sliding recordings (``tactile fit-textures``).

The robot's simulator renders the models (:mod:`tactile_descriptors_ros.sim.textures`
describes them); this module fits them: per material, an AR(p) model of PAC
from the autocovariance of 2 s segments, and per electrode a level, a linear
response to PAC and PDC and an AR(2) residual.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_descriptors_ros.errors import DataFormatError
from tactile_descriptors_ros.sim.textures import (
    BIOTAC_FRAME_RATE_HZ,
    DEFAULT_SPEED_EXPONENT,
    PDC_N_PER_COUNT,
    REFERENCE_SPEED_M_S,
    DeformationModel,
    MaterialModel,
    VibrationModel,
    autocovariance,
    yule_walker,
)

__all__ = ["fit_material", "fit_materials"]


def _segments(n_frames: int, seg_frames: int, skip_frames: int) -> list[tuple[int, int]]:
    out = []
    start = skip_frames
    while start + seg_frames <= n_frames:
        out.append((start, start + seg_frames))
        start += seg_frames
    return out


def fit_material(
    recordings: Sequence[Any],
    name: str,
    *,
    pac_order: int = 12,
    electrode_order: int = 2,
    segment_s: float = 2.0,
    skip_s: float = 0.5,
    source: Mapping[str, Any] | None = None,
) -> MaterialModel:
    """Fit a :class:`MaterialModel` to the recordings of one material.

    Parameters
    ----------
    recordings : sequence of BiotacRecording
        Trials of one material (see :mod:`tactile_descriptors_lab.datasets.biotac_slide`).
    name : str
        Material name stored in the model.
    pac_order : int, default 12
        AR order of the PAC model.
    electrode_order : int, default 2
        AR order of the electrode and PDC residuals.
    segment_s : float, default 2.0
        Statistics are taken over non-overlapping segments of this length
        (the paper's training exploration lasts 2 s), each segment's mean removed.
    skip_s : float, default 0.5
        Time skipped at the start of every trial.

    Returns
    -------
    MaterialModel
    """
    if not recordings:
        raise DataFormatError(f"no recordings for material {name!r}")
    ppf = len(recordings[0].pac) // max(1, recordings[0].n_frames)
    frame_rate = BIOTAC_FRAME_RATE_HZ
    fs = frame_rate * ppf
    seg_frames = int(round(segment_s * frame_rate))
    skip_frames = int(round(skip_s * frame_rate))
    n_el = recordings[0].electrodes.shape[0]

    pac_acs, pac_means, pdc_means, seg_logstd, seg_logpdc = [], [], [], [], []
    el_rows: list[np.ndarray] = []  # per segment: (n_el, seg_frames) mean-removed
    reg_rows: list[np.ndarray] = []  # per segment: (2, seg_frames) [pac frame mean, pdc] mean-removed
    el_means = []
    pdc_acs = []
    for rec in recordings:
        pac = rec.pac.astype(np.float64)
        for s, e in _segments(rec.n_frames, seg_frames, skip_frames):
            seg = pac[s * ppf : e * ppf]
            pac_acs.append(autocovariance(seg, pac_order))
            pac_means.append(seg.mean())
            pdc = rec.pdc[s:e].astype(np.float64)
            pdc_means.append(pdc.mean())
            if pdc.mean() > 1 and seg.std() > 0:
                seg_logstd.append(math.log(seg.std()))
                seg_logpdc.append(math.log(pdc.mean()))
            pdc_acs.append(autocovariance(pdc, electrode_order))
            el = rec.electrodes[:, s:e].astype(np.float64)
            el_means.append(el.mean(axis=1))
            el_rows.append(el - el.mean(axis=1, keepdims=True))
            fm = seg.reshape(-1, ppf).mean(axis=1)
            reg_rows.append(np.vstack([fm - fm.mean(), pdc - pdc.mean()]))
    if not pac_acs:
        raise DataFormatError(f"material {name!r}: no trial is longer than {segment_s + skip_s} s")
    a, s2 = yule_walker(np.mean(pac_acs, axis=0))

    # force exponent: slope of log PAC std against log mean PDC over segments
    force_exp = 0.5
    if len(seg_logpdc) >= 5 and np.std(seg_logpdc) > 0.05:
        slope = float(np.polyfit(seg_logpdc, seg_logstd, 1)[0])
        force_exp = float(np.clip(slope, 0.0, 1.5))

    X = np.concatenate(reg_rows, axis=1)  # (2, N)
    Y = np.concatenate(el_rows, axis=1)  # (n_el, N)
    coef, *_ = np.linalg.lstsq(X.T, Y.T, rcond=None)  # (2, n_el)
    coupling, slope_pdc = coef[0], coef[1]
    el_ar, el_s2 = [], []
    for j in range(n_el):
        acs = []
        for el, reg in zip(el_rows, reg_rows):
            resid = el[j] - coupling[j] * reg[0] - slope_pdc[j] * reg[1]
            acs.append(autocovariance(resid, electrode_order))
        r = np.mean(acs, axis=0)
        if r[0] <= 1e-9:  # an electrode that never moved: white noise of tiny variance
            el_ar.append(tuple([0.0] * electrode_order))
            el_s2.append(1e-6)
            continue
        aj, sj = yule_walker(r)
        el_ar.append(tuple(float(v) for v in aj))
        el_s2.append(float(sj))
    pdc_r = np.mean(pdc_acs, axis=0)
    if pdc_r[0] > 1e-9:
        pdc_a, pdc_s2 = yule_walker(pdc_r)
    else:
        pdc_a, pdc_s2 = np.zeros(electrode_order), 1e-6

    pdc_mean = float(np.mean(pdc_means))
    return MaterialModel(
        name=name,
        vibration=VibrationModel(
            fs_hz=fs, ar=tuple(float(v) for v in a), sigma2=s2, mean_counts=float(np.mean(pac_means)),
            force_exponent=force_exp, speed_exponent=DEFAULT_SPEED_EXPONENT,
        ),
        deformation=DeformationModel(
            fs_hz=frame_rate,
            electrode_mean=tuple(float(v) for v in np.mean(el_means, axis=0)),
            electrode_pac_coupling=tuple(float(v) for v in coupling),
            electrode_pdc_slope=tuple(float(v) for v in slope_pdc),
            electrode_ar=tuple(el_ar),
            electrode_sigma2=tuple(el_s2),
            pdc_mean_counts=pdc_mean,
            pdc_ar=tuple(float(v) for v in pdc_a),
            pdc_sigma2=float(pdc_s2),
        ),
        reference_speed_m_s=REFERENCE_SPEED_M_S,
        reference_force_n=max(pdc_mean * PDC_N_PER_COUNT, 0.05),
        friction=0.6,
        stick_slip_ratio=1.3,
        source=dict(source or {}),
    )


def fit_materials(data_dir: str | Path, trials: Iterable[int] | None = None, progress: bool = False,
                  **kwargs: Any) -> list[MaterialModel]:
    """Fit one model per material of a ``biotac_slide`` data set.

    Parameters
    ----------
    data_dir : path
        Folder holding ``raw_data/`` (see :func:`~tactile_descriptors_lab.datasets.biotac_slide.load_recordings`).
    trials : iterable of int, optional
        Trials to use (default: all found).
    progress : bool
        Show a tqdm bar on stderr.
    **kwargs
        Passed to :func:`fit_material`.
    """
    from ..datasets.biotac_slide import load_recordings

    trial_list = list(trials) if trials is not None else None
    by_mat: dict[int, list[Any]] = {}
    for rec in load_recordings(data_dir, trials=trial_list):
        by_mat.setdefault(rec.material, []).append(rec)
    iterator: Iterable[int] = sorted(by_mat)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(list(iterator), desc="fit textures", unit="material")
    models = []
    for mat in iterator:
        recs = by_mat[mat]
        name = recs[0].class_name
        src = {
            "dataset": Path(data_dir).name,
            "material": mat,
            "trials": sorted(r.trial for r in recs),
            "segment_s": kwargs.get("segment_s", 2.0),
        }
        models.append(fit_material(recs, name, source=src, **kwargs))
    return models
