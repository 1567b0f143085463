"""The public BioTac sliding recordings (``BioTac_slide_20_50`` layout), read through their shipped mapping.

Layout: ``raw_data/mat<M>/mat<M>_<N>_bio.csv``, M the material (class), N the
trial.  Each row is one 10 ms BioTac frame: ``timestamp`` (Unix seconds),
``tdc``, ``tac``, ``pdc``, ``pac1..pac22`` (22 PAC samples per frame, so PAC is
2.2 kHz), ``ele1..ele19``; every row ends with a comma.  Values are 12-bit
counts that the recording setup tared and clipped at 0.

Nothing here is special to this layout: the shipped mapping
``datasets/mappings/biotac_slide_20_50.yaml`` describes it (class names
included, from the data set's README), and :func:`~.sources.read_source`
reads it like any other table.  These functions keep the names callers use.
"""

from __future__ import annotations

from pathlib import Path

from tactile_descriptors_lab.datasets.readers import DEFAULT_MAPPING, read_source
from tactile_descriptors_lab.datasets.recording import N_ELECTRODES, BiotacRecording

__all__ = [
    "BiotacRecording",
    "read_biotac_csv",
    "load_recordings",
    "PAC_PER_FRAME",
    "N_ELECTRODES",
    "MAPPING",
]

#: PAC samples per frame in this data set.
PAC_PER_FRAME = 22
#: Name of the shipped mapping of this layout.
MAPPING = DEFAULT_MAPPING


def read_biotac_csv(path: str | Path) -> BiotacRecording:
    """Read one ``mat<M>_<N>_bio.csv`` file (through the shipped mapping).

    Raises
    ------
    DataFormatError
        If the file does not hold the mapped columns, or a row is malformed.
    ConfigError
        If the file name does not follow ``mat<M>_<N>_bio.csv``.
    """
    (rec,) = read_source(path, MAPPING)
    return rec


def load_recordings(root: str | Path, trials=None, materials=None) -> list[BiotacRecording]:
    """Every matching recording below ``root`` (the folder holding ``raw_data/``, or ``raw_data``).

    ``trials`` and ``materials`` select by number; selecting a trial or a
    material the folder does not hold is a :class:`~..errors.ConfigError`.
    """
    classes = None if materials is None else [str(int(m)) for m in materials]
    return read_source(root, MAPPING, trials=None if trials is None else list(trials), classes=classes)
