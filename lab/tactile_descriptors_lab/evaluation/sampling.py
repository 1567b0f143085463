"""Trial selection, the crop rule and seeded window positions.

The crop rule (no duration leak): in the BioTac sliding data material 1 lasts
about 6 s and the others about 8 s, so trial length alone would give a class
away.  Every trial is first cropped to the *common length* -- the shortest
trial of the data in use (599 frames = 5.99 s here) -- and every window is
then drawn inside that cropped span: a ``whole`` window is the cropped trial
itself, a shorter window starts at a uniformly random frame of the cropped
span.  All windows of one evaluation therefore have exactly the same number
of frames, and a window's position carries no class information.

Positions are drawn from a generator seeded by ``(seed, material, trial,
length)``, so they do not depend on which other trials are loaded.

Contact windows (``tactile evaluate --windows contact``) lie wholly in
contact: every frame's force (PDC x n_per_count) is at least F_t.  Their
positions are drawn among the starts where that holds, anywhere in the
trial (recordings from a gripper that opens and closes hold long stretches
out of contact, where random windows would describe nothing).  A trial
without such a stretch gives no window, and is reported.

A touch on a robot lasts what it lasts, so a window may also be a *range*
of lengths (``"1-6"``): every window then draws its length from the grid
``A, A + 0.5 s, ..., B`` (:data:`MIXED_STEP_S`; a length past the crop
becomes the crop) and its position inside the crop, both from a generator
seeded by ``(seed, material, trial, grid)``.  Length and position are drawn
independently of the class, so the crop rule still holds: no window's
length or position carries class information.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.readers import format_numbers, read_source
from tactile_descriptors_lab.datasets.recording import BiotacRecording
from tactile_descriptors_ros.core.blocks import block_starts
from tactile_descriptors_ros.errors import ConfigError

#: Block averaging of the descriptor (seconds): a window is described by the mean over its 1 s blocks,
#: at most 0.5 s apart, so that what a model learns on one touch length holds on others
#: (lab/docs/evaluation.md, "Touch length"); here, free of scikit-learn, so that the CLI
#: can show them without importing the evaluation stack.
DEFAULT_BLOCK_S: float = 1.0
DEFAULT_BLOCK_HOP_S: float = 0.5

#: Default training windows per trial: at least :data:`MIN_TRAIN_WINDOWS`, and enough windows of the
#: training length to add up to :data:`TRAIN_SECONDS_PER_TRIAL` (8 at 2 s and longer, 16 at 1 s, 32 at
#: 0.5 s).  A short window sees less of a trial, so more of them are drawn: on the development split
#: (1 s windows, 2,000 test windows) 8 per trial scored 91.4 %, 16 93.4 % and 32 93.2 % (lab/docs/evaluation.md).
MIN_TRAIN_WINDOWS: int = 8
TRAIN_SECONDS_PER_TRIAL: float = 16.0

__all__ = [
    "DEFAULT_BLOCK_S", "DEFAULT_BLOCK_HOP_S",
    "MIN_TRAIN_WINDOWS", "TRAIN_SECONDS_PER_TRIAL", "default_train_windows",
    "parse_trials",
    "format_trials",
    "common_length_frames",
    "window_frames",
    "MIXED_STEP_S",
    "is_length_range",
    "window_lengths",
    "Window",
    "draw_windows",
    "draw_contact_windows",
    "WINDOW_PLACEMENTS",
    "draw_mixed_windows",
    "block_windows",
    "load_split",
]

#: How ``tactile evaluate`` places windows: seeded random positions in the crop, or wholly in contact.
WINDOW_PLACEMENTS = ("random", "contact")

_RANGE = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+))?\s*$")


def parse_trials(text: str | Sequence[int] | None) -> list[int] | None:
    """Parse ``"1-20"``, ``"1-5,8,10-12"`` (or a sequence of ints) into a sorted list.

    ``None`` or ``"all"`` means every trial.

    Raises
    ------
    ConfigError
        For a malformed range or a range that runs backwards.
    """
    if text is None:
        return None
    if not isinstance(text, str):
        out = sorted({int(t) for t in text})
        if not out or out[0] < 1:
            raise ConfigError(f"trial numbers must be >= 1, got {list(text)!r}")
        return out
    if text.strip().lower() == "all":
        return None
    out: set[int] = set()
    for part in text.split(","):
        m = _RANGE.match(part)
        if not m:
            raise ConfigError(f"bad trial range {part!r} (expected e.g. 1-20 or 1-5,8)", key="trials")
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) else lo
        if hi < lo or lo < 1:
            raise ConfigError(f"bad trial range {part!r}: must be increasing and >= 1", key="trials")
        out.update(range(lo, hi + 1))
    return sorted(out)


def format_trials(trials: Sequence[int] | None) -> str:
    """Inverse of :func:`parse_trials` (compact ``a-b,c`` form)."""
    return "all" if trials is None else format_numbers(trials)


def common_length_frames(recordings: Sequence[BiotacRecording]) -> int:
    """The crop length: the frame count of the shortest recording."""
    if not recordings:
        raise ConfigError("no recordings to crop")
    return int(min(r.n_frames for r in recordings))


def window_frames(window: str | float, frame_rate_hz: float, common_frames: int) -> int:
    """Frames per window: ``"whole"`` is the common length, else ``round(seconds * rate)``.

    Raises
    ------
    ConfigError
        When the window is not positive or longer than the common length.
    """
    if isinstance(window, str):
        if window.strip().lower() == "whole":
            return int(common_frames)
        try:
            window = float(window)
        except ValueError:
            raise ConfigError(f"window must be seconds or 'whole', got {window!r}", key="window") from None
    n = int(round(float(window) * frame_rate_hz))
    if n < 3:
        raise ConfigError(f"window of {window} s is shorter than 3 frames", key="window")
    if n > common_frames:
        raise ConfigError(
            f"window of {window} s ({n} frames) is longer than the common trial length "
            f"({common_frames} frames = {common_frames / frame_rate_hz:.2f} s)", key="window")
    return n


#: Step of the length grid of a window range such as ``"1-6"`` (seconds).
MIXED_STEP_S: float = 0.5

_LENGTH_RANGE = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*-\s*(\d+(?:\.\d*)?)\s*$")


def is_length_range(window: str | float) -> bool:
    """True for a window given as a range of lengths in seconds (``"1-6"``)."""
    return isinstance(window, str) and _LENGTH_RANGE.match(window) is not None


def window_lengths(window: str | float, frame_rate_hz: float, common_frames: int) -> tuple[int, ...]:
    """Frame counts a window specification allows, shortest first.

    ``"2"`` or ``"whole"`` give one length (:func:`window_frames`); a range
    ``"A-B"`` gives the grid ``A, A + MIXED_STEP_S, ..., B`` seconds, each
    rounded to frames, a length longer than the crop replaced by the crop
    (so ``"1-6"`` on 5.99 s trials ends with the whole crop).

    Raises
    ------
    ConfigError
        For a range that runs backwards, starts below 3 frames or starts past the crop.
    """
    m = _LENGTH_RANGE.match(window) if isinstance(window, str) else None
    if m is None:
        return (window_frames(window, frame_rate_hz, common_frames),)
    lo_s, hi_s = float(m.group(1)), float(m.group(2))
    if hi_s <= lo_s:
        raise ConfigError(f"window range {window!r} must run from a shorter to a longer length", key="window")
    first = window_frames(lo_s, frame_rate_hz, common_frames)  # checks >= 3 frames and inside the crop
    n_steps = int(np.floor((hi_s - lo_s) / MIXED_STEP_S + 1e-9))
    grid = [min(int(round((lo_s + k * MIXED_STEP_S) * frame_rate_hz)), int(common_frames))
            for k in range(n_steps + 1)]
    return tuple(sorted({first, *grid}))


def default_train_windows(lengths_frames: Sequence[int], frame_rate_hz: float) -> int:
    """Training windows per trial when none is given: ``max(8, ceil(16 s / shortest length))``.

    Parameters
    ----------
    lengths_frames : sequence of int
        The lengths a training window may have (:func:`window_lengths`).
    frame_rate_hz : float

    Returns
    -------
    int
        :data:`MIN_TRAIN_WINDOWS`, or more for windows shorter than
        :data:`TRAIN_SECONDS_PER_TRIAL` / :data:`MIN_TRAIN_WINDOWS` seconds.
    """
    shortest_s = min(int(n) for n in lengths_frames) / float(frame_rate_hz)
    return max(MIN_TRAIN_WINDOWS, int(np.ceil(TRAIN_SECONDS_PER_TRIAL / shortest_s - 1e-9)))


@dataclass(frozen=True)
class Window:
    """One window: frames ``start:start + n_frames`` of one recording."""

    material: int
    trial: int
    start: int
    n_frames: int


def draw_windows(recordings: Sequence[BiotacRecording], n_frames: int, common_frames: int,
                 per_trial: int = 1, seed: int = 0) -> list[Window]:
    """Seeded random window positions inside each trial's common-length crop.

    Parameters
    ----------
    recordings : sequence of BiotacRecording
    n_frames : int
        Window length in frames (every window has exactly this length).
    common_frames : int
        Crop length; windows lie in frames ``0:common_frames`` of every trial.
    per_trial : int, default 1
        Windows per trial.  When the window is the whole crop there is only
        one position and ``per_trial`` is ignored.
    seed : int

    Returns
    -------
    list of Window, ordered as the recordings.
    """
    if n_frames > common_frames:
        raise ConfigError(f"window ({n_frames} frames) longer than the crop ({common_frames})")
    out = []
    span = common_frames - n_frames
    for r in recordings:
        if r.n_frames < common_frames:
            raise ConfigError(f"{r.path}: {r.n_frames} frames, shorter than the crop ({common_frames})")
        if span == 0:
            out.append(Window(r.material, r.trial, 0, n_frames))
            continue
        rng = np.random.default_rng([int(seed), int(r.material), int(r.trial), int(n_frames)])
        for start in rng.integers(0, span + 1, size=per_trial):
            out.append(Window(r.material, r.trial, int(start), n_frames))
    return out


def draw_contact_windows(recordings: Sequence[BiotacRecording], n_frames: int, per_trial: int, seed: int,
                         n_per_count: float, force_threshold_n: float
                         ) -> tuple[list[Window], list[BiotacRecording]]:
    """Seeded random windows lying wholly in contact (every frame's force >= F_t).

    Parameters
    ----------
    recordings : sequence of BiotacRecording
    n_frames : int
        Window length in frames.
    per_trial : int
        Windows per trial (fewer when the trial has fewer contact positions; drawn without repetition).
    seed : int
    n_per_count : float
        Force per PDC count (the cell type's force scale).
    force_threshold_n : float
        F_t (eq. 13).

    Returns
    -------
    windows : list of Window
    without : list of BiotacRecording
        Trials with no window of ``n_frames`` in contact (they give no window).
    """
    out: list[Window] = []
    without: list[BiotacRecording] = []
    for r in recordings:
        contact = r.force_n(n_per_count) >= force_threshold_n
        if r.n_frames < n_frames:
            without.append(r)
            continue
        # a start s is valid when frames s .. s + n_frames - 1 are all in contact
        run = np.convolve(contact.astype(np.int64), np.ones(n_frames, dtype=np.int64), mode="valid")
        starts = np.flatnonzero(run == n_frames)
        if starts.size == 0:
            without.append(r)
            continue
        rng = np.random.default_rng([int(seed), int(r.material), int(r.trial), int(n_frames), 1])
        chosen = np.sort(rng.choice(starts, size=min(per_trial, starts.size), replace=False))
        out.extend(Window(r.material, r.trial, int(s), n_frames) for s in chosen)
    return out, without
def draw_mixed_windows(recordings: Sequence[BiotacRecording], lengths_frames: Sequence[int],
                       common_frames: int, per_trial: int = 1, seed: int = 0) -> list[Window]:
    """Seeded random windows whose lengths are drawn uniformly from ``lengths_frames``.

    Each window draws its length, then its start inside the crop, from a
    generator seeded by ``(seed, material, trial, lengths)``; class and
    length are independent.

    Returns
    -------
    list of Window, ordered as the recordings (``per_trial`` per recording).
    """
    lengths = sorted({int(n) for n in lengths_frames})
    if not lengths or lengths[-1] > common_frames or lengths[0] < 3:
        raise ConfigError(f"window lengths {lengths} must lie in 3..{common_frames} frames (the crop)")
    out = []
    for r in recordings:
        if r.n_frames < common_frames:
            raise ConfigError(f"{r.path}: {r.n_frames} frames, shorter than the crop ({common_frames})")
        rng = np.random.default_rng([int(seed), int(r.material), int(r.trial), *lengths])
        for _ in range(per_trial):
            n = int(lengths[int(rng.integers(len(lengths)))])
            out.append(Window(r.material, r.trial, int(rng.integers(0, common_frames - n + 1)), n))
    return out


def block_windows(window: Window, block_frames: int, hop_frames: int) -> list[Window]:
    """The blocks a window is described by (block averaging): the core's :func:`~..core.blocks.block_starts`.

    A window no longer than a block is its own single block.

    Raises
    ------
    ConfigError
        For a block shorter than 3 frames or a hop that is not in ``1..block_frames``.
    """
    starts = block_starts(window.n_frames, block_frames, hop_frames)
    if starts.size == 1:
        return [window]
    return [Window(window.material, window.trial, window.start + int(s), block_frames) for s in starts.tolist()]


def load_split(data_dir: str | Path, trials: Sequence[int] | None,
               materials: Sequence[int | str] | None = None, mapping: str | Path | None = None,
               report=None) -> list[BiotacRecording]:
    """Load the recordings of a split from any source :func:`~..datasets.sources.read_source` reads.

    ``materials`` selects classes by number or name.  Selecting trials or
    classes the source does not hold is a :class:`ConfigError` naming what it holds.
    """
    classes = None if materials is None else [str(m) for m in materials]
    return read_source(data_dir, mapping, trials=None if trials is None else list(trials), classes=classes,
                       report=report)
