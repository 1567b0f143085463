"""Wrapping counters made whole: the one place where sequence numbers and device clocks are unwrapped.

Every stream of this package numbers its frames with a short wrapping
counter: 8 bits per skin cell and modality (a 1 kHz accelerometer wraps every
256 ms), 16 bits per BioTac on the serial bridge, 32 bits per message, and
the bridge's microsecond clock wraps at 2^32.  Unwrapping by the nearest
difference alone (a jump of more than half the modulus counts as a step
back) turns a quiet period longer than half a wrap into a shifted clock: a
skin cell silent for 200 ms comes back 256 ms early.

:func:`unwrap` therefore takes an *expected advance* besides the previous
value: when the arrival times of two frames are known, the elapsed time
divided by the sample period says roughly how many frames should lie between
them, and the unwrapped number is the one congruent to the received number
that is nearest to that expectation.  The answer is exact while the time
error (latency jitter of the time source) stays below half a wrap; without a
time it is the plain nearest unwrapping.

:class:`SequenceTracker` applies this per key (a chip select, a cell and
modality) and classifies each number (:class:`SequenceEvent`): in order, a
gap (lost frames, counted with their length), a duplicate, a late
(reordered) frame, or a restart of the sender's count.  The codecs use it to
drop duplicates; the streams use it to number samples for their time stamps.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from enum import IntEnum

import numpy as np

from ..errors import ConfigError

__all__ = ["unwrap", "unwrap_array", "Unwrapper", "SequenceEvent", "SequenceTracker"]


def unwrap(raw: int, reference: int, modulus: int, advance: float = 0.0) -> int:
    """The integer congruent to ``raw`` modulo ``modulus`` nearest to ``reference + advance``.

    Parameters
    ----------
    raw : int
        Received counter value (any integer; taken modulo ``modulus``).
    reference : int
        Unwrapped value of an earlier frame.
    modulus : int
        The counter runs ``0..modulus-1``.
    advance : float
        Expected distance from ``reference`` (elapsed time / period); 0
        without a time.

    Notes
    -----
    A tie (exactly half a wrap from the expectation) goes to the earlier
    value, so without a time a jump of ``modulus / 2`` counts as a step back.
    """
    m = int(modulus)
    d = (int(raw) - int(reference)) % m
    j = math.ceil((float(advance) - d) / m - 0.5)
    return int(reference) + d + j * m


def unwrap_array(raw: np.ndarray, reference: np.ndarray, modulus: int,
                 advance: np.ndarray | float = 0.0) -> np.ndarray:
    """:func:`unwrap` element by element (int64 arrays; ``advance`` broadcast)."""
    m = int(modulus)
    d = (np.asarray(raw, dtype=np.int64) - np.asarray(reference, dtype=np.int64)) % m
    j = np.ceil((np.asarray(advance, dtype=np.float64) - d) / m - 0.5).astype(np.int64)
    return np.asarray(reference, dtype=np.int64) + d + j * m


class Unwrapper:
    """One wrapping counter (a device clock, a message sequence) unwrapped to a growing integer.

    Parameters
    ----------
    modulus : int
        The counter runs ``0..modulus-1``.
    """

    def __init__(self, modulus: int) -> None:
        self.modulus = int(modulus)
        self.value: int | None = None

    def __call__(self, raw: int, advance: float = 0.0) -> int:
        """The unwrapped value of ``raw`` (the first value is ``raw`` itself)."""
        if self.value is None:
            self.value = int(raw) % self.modulus
        else:
            self.value = unwrap(raw, self.value, self.modulus, advance)
        return self.value

    def reset(self) -> None:
        """Forget the history (the device restarted)."""
        self.value = None


class SequenceEvent(IntEnum):
    """What one sequence number means relative to those seen before."""

    FIRST = 0  #: first frame of this key
    IN_ORDER = 1  #: exactly the next number
    GAP = 2  #: later than the next number: frames were lost in between
    DUPLICATE = 3  #: seen recently: drop it
    LATE = 4  #: earlier than the newest but not seen: arrived out of order (accept it)
    RESET = 5  #: far earlier than the newest: the sender restarted its count (tracking restarts)


class SequenceTracker:
    """Track wrapping sequence numbers per key (a chip select, a cell and modality, ...).

    Numbers are unwrapped relative to the newest one with :func:`unwrap`.
    Given the frame times (``t_ns``) and the nominal frame period
    (``period_ns``), the elapsed time since the newest frame is the expected
    advance, so a silence of any length is a gap of the right length; without
    times a difference of more than half the modulus counts as "earlier".
    The last ``window`` numbers are remembered so that duplicates are
    recognised even after reordering.  A number more than ``window`` before
    the newest means the sender restarted (a replugged sensor, a rebooted
    bridge): tracking of that key restarts.

    ``lost`` is the net number of frames missing inside the span seen so far:
    it grows on gaps and shrinks when a late frame fills a hole.

    Parameters
    ----------
    modulus : int
        Sequence numbers run ``0..modulus-1`` and wrap.
    window : int
        How many recent numbers are remembered for duplicate detection (and
        how far back a number means a restart); 0 for a stream whose
        duplicates were already removed (no memory kept, nothing is a
        duplicate, a step back of more than ``modulus / 8`` is a restart).
    period_ns : float, optional
        Default frame period of every key (``track_many`` also takes one per
        number); without it times are ignored.
    """

    def __init__(self, modulus: int, window: int = 64, period_ns: float | None = None) -> None:
        if modulus < 4 or window < 0 or window >= modulus // 2:
            raise ConfigError(f"bad sequence tracker (modulus {modulus}, window {window})")
        self.modulus = int(modulus)
        self.window = int(window)
        self.period_ns = None if period_ns is None else float(period_ns)
        self._state: dict[Hashable, tuple[int, int, set[int]]] = {}  # key -> (low, high, seen)
        self._t_high: dict[Hashable, int] = {}  # key -> time of the newest number [ns]
        self.gaps = 0
        self.lost = 0
        self.duplicates = 0
        self.late = 0
        self.resets = 0
        self._last_unwrapped = 0

    def reset(self, key: Hashable | None = None) -> None:
        """Forget one key (e.g. a sensor that was replugged) or all keys."""
        if key is None:
            self._state.clear()
            self._t_high.clear()
        else:
            self._state.pop(key, None)
            self._t_high.pop(key, None)

    def newest(self, key: Hashable) -> int | None:
        """The unwrapped newest number of ``key`` (``None`` before its first)."""
        st = self._state.get(key)
        return None if st is None else st[1]

    def update(self, key: Hashable, seq: int, t_ns: int | None = None,
               period_ns: float | None = None) -> SequenceEvent:
        """Register ``seq`` (received at ``t_ns``, optional) for ``key`` and say what it was."""
        event, self._last_unwrapped = self.track(key, seq, t_ns, period_ns)
        return event

    def track(self, key: Hashable, seq: int, t_ns: int | None = None,
              period_ns: float | None = None) -> tuple[SequenceEvent, int]:
        """:meth:`update`, also returning the unwrapped number (meaningless for a duplicate)."""
        m = self.modulus
        seq = int(seq) % m
        st = self._state.get(key)
        if st is None:
            self._state[key] = (seq, seq, {seq} if self.window else set())
            self._set_time(key, t_ns)
            return SequenceEvent.FIRST, seq
        low, high, seen = st
        period = self.period_ns if period_ns is None else period_ns
        t_high = self._t_high.get(key)
        advance = (t_ns - t_high) / period if (t_ns is not None and t_high is not None and period) else 0.0
        u = unwrap(seq, high, m, advance)
        if u < high - (self.window or m // 8):
            self.resets += 1
            self._state[key] = (seq, seq, {seq} if self.window else set())
            self._set_time(key, t_ns)
            return SequenceEvent.RESET, seq
        if self.window and u in seen:
            self.duplicates += 1
            return SequenceEvent.DUPLICATE, u
        if self.window:
            seen.add(u)
        if u > high:
            event = SequenceEvent.IN_ORDER if u == high + 1 else SequenceEvent.GAP
            if u > high + 1:
                self.gaps += 1
                self.lost += u - high - 1
            high = u
            self._set_time(key, t_ns)
            if len(seen) > 2 * self.window + 2:
                cut = high - self.window
                seen = {x for x in seen if x >= cut}
        elif u < low:
            self.late += 1
            self.lost += low - u - 1
            low = u
            event = SequenceEvent.LATE
        else:
            self.late += 1
            self.lost -= 1
            event = SequenceEvent.LATE
        self._state[key] = (low, high, seen)
        return event, u

    def track_run(self, key: Hashable, first: int, count: int) -> tuple[SequenceEvent, int]:
        """Register a run of ``count`` consecutive numbers from ``first`` (one message of a batch).

        For a tracker without duplicate memory (``window=0``), as the
        messages of one publisher need: they arrive in order, so a run that
        starts at or before the newest number is a restart of the sender's
        count (a node started again, a bag replayed again), never a late run.

        Returns
        -------
        event : SequenceEvent
            What the run's first number was (``GAP``: numbers were lost before it).
        lost : int
            Numbers lost between the previous run and this one (0 unless ``GAP``).
        """
        if self.window:
            raise ConfigError("track_run needs a tracker without duplicate memory (window=0)")
        if count < 1:
            raise ConfigError(f"a run holds at least one number, not {count}")
        m = self.modulus
        first = int(first) % m
        st = self._state.get(key)
        if st is None:
            self._state[key] = (first, first + count - 1, set())
            return SequenceEvent.FIRST, 0
        low, high, seen = st
        u = unwrap(first, high + 1, m)
        if u <= high:
            self.resets += 1
            self._state[key] = (first, first + count - 1, set())
            return SequenceEvent.RESET, 0
        lost = u - high - 1
        if lost:
            self.gaps += 1
            self.lost += lost
        self._state[key] = (low, u + count - 1, seen)
        return (SequenceEvent.GAP if lost else SequenceEvent.IN_ORDER), lost

    def _set_time(self, key: Hashable, t_ns: int | None) -> None:
        if t_ns is None:
            self._t_high.pop(key, None)
        else:
            self._t_high[key] = int(t_ns)

    def update_many(self, codes: np.ndarray, seqs: np.ndarray, key_of: Callable[[int], Hashable],
                    t_ns: np.ndarray | None = None, period_ns: np.ndarray | float | None = None) -> np.ndarray:
        """Register many numbers at once; the events of :meth:`track_many`."""
        return self.track_many(codes, seqs, key_of, t_ns, period_ns)[0]

    def track_many(self, codes: np.ndarray, seqs: np.ndarray, key_of: Callable[[int], Hashable],
                   t_ns: np.ndarray | None = None, period_ns: np.ndarray | float | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Register many numbers at once; the same events, counters and unwrapped numbers as
        :meth:`track` one by one.

        Keys are independent, so the numbers are taken key by key (in their
        order within each key).  A key whose numbers all move forward (the
        usual case: in order or with gaps) is handled with array operations;
        any other key (duplicates, late frames, restarts) goes through
        :meth:`track` number by number.

        Parameters
        ----------
        codes : array of int, shape (n,)
            An integer code of each number's key.
        seqs : array of int, shape (n,)
            The sequence numbers, in arrival order.
        key_of : callable(int) -> hashable
            The key of a code, as :meth:`track` would be given it (so the
            two methods can be mixed on one tracker).
        t_ns : array of int, shape (n,), optional
            Arrival (or bus) time of each number [ns]; a negative value
            means unknown.
        period_ns : float or array of float, shape (n,), optional
            Frame period of each number's key (default ``period_ns`` of the
            tracker).

        Returns
        -------
        events : numpy.ndarray of int8, shape (n,)
            The :class:`SequenceEvent` of each number.
        unwrapped : numpy.ndarray of int64, shape (n,)
            The unwrapped number of each (meaningless for a duplicate).
        """
        codes = np.asarray(codes, dtype=np.int64)
        n = codes.size
        events = np.empty(n, dtype=np.int8)
        unwrapped_out = np.empty(n, dtype=np.int64)
        if not n:
            return events, unwrapped_out
        m = self.modulus
        order = np.argsort(codes, kind="stable")
        sc = codes[order]
        ss = np.asarray(seqs, dtype=np.int64)[order] % m
        starts = np.flatnonzero(np.r_[True, sc[1:] != sc[:-1]])
        ends = np.r_[starts[1:], n]
        lens = ends - starts
        keys = [key_of(c) for c in sc[starts].tolist()]
        states = [self._state.get(k) for k in keys]
        is_new = np.array([st is None for st in states], dtype=bool)
        high = np.array([0 if st is None else st[1] for st in states], dtype=np.int64)
        # expected advance between neighbours of a key, from their times
        period = self.period_ns if period_ns is None else period_ns
        if t_ns is not None and period is not None:
            tt = np.asarray(t_ns, dtype=np.int64)[order]
            pp = np.broadcast_to(np.asarray(period, dtype=np.float64), (n,))
            pp = pp[order] if np.ndim(period) else pp
            t_prev = np.empty(n, dtype=np.int64)
            t_prev[1:] = tt[:-1]
            t_prev[starts] = [self._t_high.get(k, -1) for k in keys]
            known = (tt >= 0) & (t_prev >= 0) & (pp > 0)
            advance = np.where(known, (tt - t_prev) / np.where(pp > 0, pp, 1.0), 0.0)
        else:
            tt = None
            advance = np.zeros(n)
        prev = np.empty(n, dtype=np.int64)
        prev[1:] = ss[:-1]
        prev[starts] = high
        diff = unwrap_array(ss, prev, m, advance) - prev
        diff[starts[is_new]] = 1  # placeholder, the FIRST number of a new key
        fast = np.minimum.reduceat(diff, starts) > 0
        base = np.where(is_new, ss[starts] - 1, high)
        cs = np.cumsum(diff)
        before = cs[starts] - diff[starts]
        unwrapped = cs + np.repeat(base - before, lens)
        ev = np.where(diff == 1, SequenceEvent.IN_ORDER, SequenceEvent.GAP).astype(np.int8)
        ev[starts[is_new]] = SequenceEvent.FIRST
        in_fast = np.repeat(fast, lens)
        gap = in_fast & (diff > 1)
        self.gaps += int(gap.sum())
        self.lost += int((diff[gap] - 1).sum())
        u_list = unwrapped.tolist()
        s_list = ss.tolist()
        t_list = None if tt is None else tt.tolist()
        p_list = None if tt is None else pp.tolist()
        w = self.window
        for g, (a, b) in enumerate(zip(starts.tolist(), ends.tolist())):
            key = keys[g]
            if fast[g]:
                st = states[g]
                if st is None:
                    low, seen = s_list[a], set()
                else:
                    low, _, seen = st
                if w:
                    seen.update(u_list[a:b])
                new_high = u_list[b - 1]
                if len(seen) > 2 * w + 2:
                    cut = new_high - w
                    seen = {x for x in seen if x >= cut}
                self._state[key] = (low, new_high, seen)
                self._set_time(key, None if t_list is None or t_list[b - 1] < 0 else t_list[b - 1])
            else:
                for i in range(a, b):
                    t_i = None if t_list is None or t_list[i] < 0 else t_list[i]
                    ev[i] = self.update(key, s_list[i], t_i, None if p_list is None else p_list[i])
                    unwrapped[i] = self._last_unwrapped
        events[order] = ev
        unwrapped_out[order] = unwrapped
        return events, unwrapped_out
