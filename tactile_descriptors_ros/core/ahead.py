"""Describe an exploration's window while its release time runs.

An exploration ends once every cell has stayed below the release threshold
for ``release_s`` (0.1 s on the shipped robots); its window is
``[onset, release)``, where ``release`` is the first stamp of that quiet
time (:mod:`.windowing`).  So the window is known ``release_s`` before the
release is decided: from the poll that first finds every cell below the
threshold (:meth:`~.windowing.Windower.closing_exploration`), the exploration
either ends as that window or goes on because a cell touches again.

:class:`DescribeAhead` describes that window then
(:meth:`~.windowing.Windower.cut_ahead`), and when the windower closes the
exploration it hands back the descriptor made ahead, instead of describing
again, if the window at the decision holds the same samples, bit for bit:
the windower returns the very window it cut ahead when no sample inside
its span and no new tare reached it since (a few array operations per
buffer, without cutting again), and a window cut again is compared with it
(:func:`same_window`).  Otherwise (samples of the window that arrived late,
a new tare) the caller describes the final window as before: the descriptor
published is the same bits either way, and a replayed bag gives the same
output whether or not a description was made ahead.  What it saves is the
time from the release decision to the descriptor: a NAO window's 10 ms of
describing move into the release time, where nothing waits for them.

The cost is the descriptions of windows that do not close as cut: a cell
that touches again within ``release_s`` (counted, ``discarded``).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

import numpy as np

from ..errors import SignalError
from .windowing import Window, Windower

__all__ = ["DescribeAhead", "same_bits", "same_window"]

T = TypeVar("T")

#: :class:`~.aggregation.CellStacks`' arrays (a stacked cell's arrays are their rows)
_STACKED = ("vibration", "vibration_t_ns", "deformation", "deformation_t_ns", "force_n", "extra")
#: The other fields of :class:`~.aggregation.CellSignals`
_OWN = ("valid", "gap", "invalid_samples", "deformation_tare")
_ALL = _STACKED + _OWN


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays (views too) have one dtype and shape and the same bytes per element: floats are
    compared as integers, so NaN equals its own bits and -0.0 differs from 0.0."""
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind in "fc":
        as_int = np.dtype(f"u{a.dtype.itemsize // 2 if a.dtype.kind == 'c' else a.dtype.itemsize}")
        a, b = a.view(as_int), b.view(as_int)
    return bool(np.array_equal(a, b))


def _same(x, y) -> bool:
    """Same bits (:func:`same_bits`) for arrays, equal values of one type else."""
    if isinstance(x, np.ndarray) and isinstance(y, np.ndarray):
        return same_bits(x, y)
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return False
    return x is y or (x == y and type(x) is type(y))


def _stack_rows(window: Window) -> dict[int, int] | None:
    """Each cell's row in the window's stacks, when every cell is a row it still holds (else None)."""
    stacks = window.stacks
    if stacks is None or not stacks.holds(list(stacks.cells), *_STACKED):
        return None
    rows = {id(cell): k for k, cell in enumerate(stacks.cells)}
    out = {}
    for cid, cell in window.cells.items():
        if (k := rows.get(id(cell))) is None:
            return None
        out[cid] = k
    return out


def same_window(a: Window, b: Window) -> bool:
    """Whether two windows hold the same samples: span, exploration id and mode, the same cells in the same
    order, and every cell's arrays (dtype, shape, bits) and flags equal.

    Windows cut as one set of stacks (:class:`~.aggregation.CellStacks`) are
    compared stack by stack, a few calls for the whole robot (a NAO window:
    116 cells); others cell by cell.
    """
    if (a.start_ns, a.end_ns, a.exploration_id, a.mode) != (b.start_ns, b.end_ns, b.exploration_id, b.mode):
        return False
    if list(a.cells) != list(b.cells):
        return False
    if (a.stacks is None) != (b.stacks is None):
        return False
    fields = _ALL
    rows = _stack_rows(a)
    if rows is not None and rows == _stack_rows(b):
        if not all(_same(getattr(a.stacks, f), getattr(b.stacks, f)) for f in _STACKED):
            return False
        fields = _OWN
    return all(_same(getattr(ca, f), getattr(b.cells[cid], f)) for cid, ca in a.cells.items() for f in fields)


class DescribeAhead(Generic[T]):
    """Descriptions of exploration windows made during their release time (module docstring).

    Parameters
    ----------
    describe : callable
        ``describe(window) -> descriptor``: what the caller publishes for a
        window.  A :class:`~..errors.SignalError` it raises ahead is left to
        the description at the decision, which reports it.
    settings : callable, optional
        ``settings() -> hashable``: the caller's settings the description
        depends on besides the window (a contact threshold, a frame id).
        A description made under other settings than those at the decision
        is not handed back (``discarded``).

    Attributes
    ----------
    used : int
        Windows closed as described ahead: their descriptor was handed back.
    changed : int
        Windows closed on the same span but with other samples (late
        samples, a new tare): described again.
    discarded : int
        Descriptions made ahead whose window never closed (a cell touched
        again within ``release_s``, a stall) or that the settings changed
        since.
    """

    def __init__(self, describe: Callable[[Window], T], settings: Callable[[], Hashable] | None = None) -> None:
        self._describe = describe
        self._settings = settings or (lambda: None)
        self._made_with: Hashable = None
        self._key: tuple[int, int, int] | None = None
        self._window: Window | None = None
        self._result: T | None = None
        self.used = 0
        self.changed = 0
        self.discarded = 0

    @property
    def pending(self) -> tuple[int, int, int] | None:
        """``(start_ns, end_ns, exploration_id)`` of the window described ahead and not yet closed, or None."""
        return self._key

    def offer(self, windower: Windower) -> bool:
        """After a poll: describe the window the open exploration would close as, unless it already was.

        Returns True when a description was made now.
        """
        key = windower.closing_exploration()
        if key is None or key == self._key:
            return False
        self.clear()
        window = windower.cut_ahead()
        self._key = key
        self._made_with = self._settings()
        if window is None or not window.cells:
            return False
        try:
            self._result = self._describe(window)
        except SignalError:
            return False
        self._window = window
        return True

    def take(self, window: Window) -> T | None:
        """The descriptor made ahead for ``window`` when it holds the same samples (:func:`same_window`), else None.

        Call it with every window the windower closes, in order: a held
        description whose window did not close is dropped (``discarded``).
        """
        if self._key is None:
            return None
        if self._key != (window.start_ns, window.end_ns, window.exploration_id) or window.mode != "exploration" \
                or self._made_with != self._settings():
            self.clear()
            return None
        ahead, result = self._window, self._result
        self._key = self._window = self._result = None
        if ahead is None:  # described ahead without a result (it failed): describe it now
            return None
        if window is ahead or same_window(ahead, window):  # the windower hands back the window it cut ahead
            self.used += 1
            return result
        self.changed += 1
        return None

    def clear(self) -> None:
        """Drop what is held (counted as ``discarded`` when a description was made): the settings changed, or
        its window will not close as cut."""
        if self._window is not None:
            self.discarded += 1
        self._key = self._window = self._result = None

    def counts(self) -> dict[str, int]:
        """``used``, ``changed`` and ``discarded`` (for diagnostics)."""
        return {"used": self.used, "changed": self.changed, "discarded": self.discarded}
