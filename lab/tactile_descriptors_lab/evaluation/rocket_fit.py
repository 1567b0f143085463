"""Fit the ``rocket`` feature group's transforms (:mod:`tactile_descriptors_ros.core.rocket`) on training recordings.

The training series are the 1 s blocks the window node describes (block
averaging: ``descriptor.block_s``), taken from the training windows that
``tactile evaluate`` draws (seeded random positions in the common-length
crop, :func:`~.sampling.draw_windows`), so the biases are quantiles of the
signals the group will see.  Two transforms per cell type:

* ``vibration``: the vibration channels (a BioTac's PAC at 2.2 kHz), with
  dilations 1 to 12 only (:data:`VIBRATION_MAX_DILATION`): on the shared
  BioTac recordings (1 s windows, ridge on the fused features) the
  dilations 22-274 added nothing the small ones and the other groups did not
  carry (95.5 % on the development split and 96.2 +- 1.1 % by trial
  cross-validation with dilations 1-12 and 420 features, 95.75 % and
  96.4 +- 1.5 % with all nine dilations and 840) at twice the cost;
* ``slow``: the deformation channels (tare subtracted) and the extra
  channels together, as one multichannel series (840 features).

Only the fitted parameters are written (dilations, channel combinations,
biases), never the data.

:func:`transform_in_use` evaluates with another fitted file than the
config directory's (``tactile evaluate --rocket``, ``--select-rocket``).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.recording import BiotacRecording
from tactile_descriptors_lab.evaluation.bank import recording_cells, recordings_robot
from tactile_descriptors_lab.evaluation.sampling import (
    common_length_frames,
    default_train_windows,
    draw_windows,
    window_frames,
)
from tactile_descriptors_ros.core import rocket
from tactile_descriptors_ros.core.cell_types import CellType
from tactile_descriptors_ros.core.groups import rocket_parameters
from tactile_descriptors_ros.core.yamlreader import config_dir
from tactile_descriptors_ros.errors import ConfigError

__all__ = ["VIBRATION_FEATURES", "VIBRATION_MAX_DILATION", "SLOW_FEATURES", "training_blocks", "fit_rocket",
           "check_transform_file", "transform_in_use"]

#: Features of the vibration transform (5 per kernel: 2 at dilation 1, 1 at 3, 6 and 12).
VIBRATION_FEATURES: int = 420
#: Largest dilation of the vibration transform (samples).
VIBRATION_MAX_DILATION: int = 12
#: Features of the slow channels' transform.
SLOW_FEATURES: int = 840


def training_blocks(recordings: Sequence[BiotacRecording], block_s: float = 1.0, seed: int = 0,
                    per_trial: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The vibration and slow-channel series of the training windows ``tactile evaluate`` draws of ``block_s``.

    Returns
    -------
    vibration : numpy.ndarray, shape (n_windows, n_vibration_channels, n_fast)
    slow : numpy.ndarray, shape (n_windows, n_deformation + n_extra channels, n_slow)
        Deformation minus its tare, then the extra channels.
    """
    if not recordings:
        raise ConfigError("no training recordings to fit the rocket group on")
    robot, cell_type = recordings_robot(recordings)
    common = common_length_frames(recordings)
    rate = float(np.median([r.frame_rate_hz for r in recordings]))
    n = window_frames(block_s, rate, common)
    per = per_trial or default_train_windows([n], rate)
    by = {(r.material, r.trial): r for r in recordings}
    vib, slow = [], []
    for w in draw_windows(recordings, n, common, per, seed):
        sig = recording_cells(by[(w.material, w.trial)].crop_frames(w.start, w.start + n), cell_type)[0]
        dfm = np.asarray(sig.deformation, dtype=np.float64)
        if sig.deformation_tare is not None:
            dfm = dfm - np.asarray(sig.deformation_tare, dtype=np.float64)[:, None]
        extra = np.asarray(sig.extra, dtype=np.float64) if sig.extra is not None else np.zeros((0, dfm.shape[1]))
        vib.append(np.asarray(sig.vibration, dtype=np.float64))
        slow.append(np.concatenate([dfm, extra], axis=0))
    lengths = {v.shape for v in vib}
    if len(lengths) != 1:
        raise ConfigError(f"training blocks of {block_s} s hold different numbers of vibration samples "
                          f"{sorted(lengths)}: the recordings' vibration rates differ")
    return np.stack(vib), np.stack(slow)


def fit_rocket(recordings: Sequence[BiotacRecording], *, block_s: float = 1.0, seed: int = 0,
               vibration_features: int = VIBRATION_FEATURES, slow_features: int = SLOW_FEATURES,
               vibration_max_dilation: int = VIBRATION_MAX_DILATION) -> dict[str, rocket.RocketParameters]:
    """Fit the ``vibration`` and ``slow`` transforms on training recordings (:func:`training_blocks`).

    Returns
    -------
    dict of str to RocketParameters
        What :func:`tactile_descriptors_ros.core.rocket.save_parameters` writes and
        :func:`tactile_descriptors_ros.core.groups.rocket_parameters` reads.
    """
    vib, slow = training_blocks(recordings, block_s, seed)
    dil_len = min(vib.shape[2], 8 * int(vibration_max_dilation) + 1)
    return {"vibration": rocket.fit(vib, vibration_features, seed=seed, n_samples=dil_len),
            "slow": rocket.fit(slow, slow_features, seed=seed + 1)}


def write_rocket(path: str | Path, params: dict[str, rocket.RocketParameters], description: str) -> Path:
    """Write fitted transforms (:func:`tactile_descriptors_ros.core.rocket.save_parameters`); return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rocket.save_parameters(path, params, description=description)
    return path


def check_transform_file(path: str | Path, *, key: str = "rocket") -> None:
    """Refuse a path that is not a transforms file ``tactile fit-rocket`` could have written.

    Raises
    ------
    ConfigError
        Naming ``key`` and the file: missing, not JSON, another format, inconsistent arrays.
    """
    if not Path(path).is_file():
        raise ConfigError(f"rocket transform {path}: no such file", key=key)
    try:
        rocket.load_parameters(path)
    except ConfigError as exc:
        raise ConfigError(str(exc), key=key) from None


@contextmanager
def transform_in_use(path: str | Path | None, cell_type: CellType, *, key: str = "rocket") -> Iterator[Path | None]:
    """Describe with the transforms of ``path`` (a file ``tactile fit-rocket`` wrote) inside the block.

    The feature engine reads a cell type's transforms from one place, the
    config directory's ``rocket/<cell type>.json``
    (:func:`~tactile_descriptors_ros.core.groups.rocket_parameters`).  This
    makes a directory of links to the config directory's entries, with
    ``path`` as the cell type's transform, and points ``TACTILE_CONFIG_DIR``
    at it for the block (restored afterwards, also on an error): what a user
    does by hand with a copy of ``config/``, so the node, the evaluation and
    the bank cache (keyed by the transform's digest) all read the same file.
    ``path`` None changes nothing.

    Yields
    ------
    pathlib.Path or None
        ``path`` resolved.

    Raises
    ------
    ConfigError
        Naming ``key`` when the file is missing, is not a transform file, or
        does not fit the cell type's channels (checked on entry).
    """
    if path is None:
        yield None
        return
    check_transform_file(path, key=key)
    src = Path(path).resolve()
    base = config_dir()
    name = f"{cell_type.name}.json"
    before = os.environ.get("TACTILE_CONFIG_DIR")
    with tempfile.TemporaryDirectory(prefix="tactile-config-") as tmp:
        root = Path(tmp)
        for entry in base.iterdir():
            if entry.name != "rocket":
                (root / entry.name).symlink_to(entry.resolve())
        (root / "rocket").mkdir()
        for entry in (base / "rocket").glob("*.json") if (base / "rocket").is_dir() else ():
            if entry.name != name:
                (root / "rocket" / entry.name).symlink_to(entry.resolve())
        (root / "rocket" / name).symlink_to(src)
        os.environ["TACTILE_CONFIG_DIR"] = str(root)
        try:
            try:
                rocket_parameters(cell_type, key=key)
            except ConfigError as exc:  # named by the link: name the file given
                raise ConfigError(str(exc).replace(str(root / "rocket" / name), str(path)), key=key) from None
            yield src
        finally:
            if before is None:
                os.environ.pop("TACTILE_CONFIG_DIR", None)
            else:
                os.environ["TACTILE_CONFIG_DIR"] = before
