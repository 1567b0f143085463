"""The one sequence tracker: wrapping numbers unwrapped with their times as well as their values."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs.sequence import SequenceEvent, SequenceTracker, Unwrapper, unwrap, unwrap_array

MS = 1_000_000


def test_unwrap_without_time_is_the_nearest_value_and_a_half_wrap_is_a_step_back():
    assert unwrap(3, 254, 256) == 259
    assert unwrap(250, 2, 256) == -6
    assert unwrap(130, 2, 256) == 130 - 256  # exactly half a wrap away counts as earlier
    assert unwrap(129, 2, 256) == 129


def test_unwrap_with_the_expected_advance_picks_the_whole_number_of_wraps():
    # 200 frames of silence: the number went 56 "back", the time says 200 forward
    assert unwrap(200, 0, 256, advance=200.0) == 200
    # 300 frames after number 200: 244 is 44 ahead, plus one whole wrap
    assert unwrap(244, 200, 256, advance=300.2) == 500
    # a late (reordered) frame just before the newest stays just before
    assert unwrap(9, 10, 256, advance=-0.8) == 9
    assert unwrap_array(np.array([200, 244]), np.array([0, 200]), 256, np.array([200.0, 300.2])).tolist() == [200, 500]


def test_tracker_counts_silences_longer_than_a_wrap_with_their_length():
    """A 1 kHz stream silent for 200 ms, then for 300 ms: two gaps of 199 and 299 lost frames."""
    t = SequenceTracker(256, window=32, period_ns=MS)
    assert t.track("c", 0, 0) == (SequenceEvent.FIRST, 0)
    assert t.track("c", 200, 200 * MS) == (SequenceEvent.GAP, 200)
    assert t.track("c", 500 % 256, 500 * MS) == (SequenceEvent.GAP, 500)
    assert (t.gaps, t.lost, t.resets) == (2, 199 + 299, 0)
    # without times the same numbers are a restart and a short gap: what the time fixes
    blind = SequenceTracker(256, window=32)
    assert blind.update("c", 0) is SequenceEvent.FIRST
    assert blind.update("c", 200) is SequenceEvent.RESET
    assert blind.update("c", 500 % 256) is SequenceEvent.GAP and blind.lost == 43


def test_tracker_with_times_still_finds_duplicates_and_late_frames():
    t = SequenceTracker(256, window=16, period_ns=MS)
    for k in range(5):
        t.update("c", k, k * MS)
    assert t.update("c", 3, 5 * MS) is SequenceEvent.DUPLICATE
    assert t.update("c", 7, 7 * MS) is SequenceEvent.GAP
    assert t.update("c", 5, 7 * MS) is SequenceEvent.LATE
    assert t.lost == 1 and t.duplicates == 1


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(1, 700)), min_size=1, max_size=120),
       st.integers(0, 40))
def test_track_many_equals_track_one_by_one_with_times(steps, window):
    """Per key: frames with random silences (up to 700 periods, several wraps), times exact."""
    period = [MS, 4 * MS, 4 * MS, 100 * MS]
    now = {k: 0 for k in range(4)}
    codes, seqs, times, true = [], [], [], []
    for k, step in steps:
        now[k] += step
        codes.append(k)
        seqs.append(now[k] % 256)
        times.append(now[k] * period[k] + 1_700_000_000 * 10**9)
        true.append(now[k])
    codes, seqs, times = np.array(codes), np.array(seqs), np.array(times, dtype=np.int64)
    per = np.array(period, dtype=float)[codes]
    ref = SequenceTracker(256, window)
    want = [ref.track(int(c), int(s), int(t), float(p)) for c, s, t, p in zip(codes, seqs, times, per)]
    got = SequenceTracker(256, window)
    half = len(codes) // 2
    ev1, u1 = got.track_many(codes[:half], seqs[:half], int, times[:half], per[:half])
    ev2, u2 = got.track_many(codes[half:], seqs[half:], int, times[half:], per[half:])
    assert np.concatenate([ev1, ev2]).tolist() == [int(e) for e, _ in want]
    assert np.concatenate([u1, u2]).tolist() == [u for _, u in want]
    assert (got.gaps, got.lost, got.resets) == (ref.gaps, ref.lost, ref.resets)
    # and the unwrapped numbers are the true ones, relative to each key's first
    first = {}
    for c, u, tr in zip(codes.tolist(), np.concatenate([u1, u2]).tolist(), true):
        first.setdefault(c, (u, tr))
        assert u - first[c][0] == tr - first[c][1]


class ReferenceTracker:
    """The tracker's rules written plainly, as a reference: per key the set of every number received (the
    tracker keeps only the holes between them), one number at a time."""

    def __init__(self, modulus: int, window: int) -> None:
        self.m, self.w = modulus, window
        self.state: dict = {}  # key -> [low, high, time of high (None = unknown), received numbers]
        self.gaps = self.lost = self.duplicates = self.late = self.resets = 0

    def track(self, key, seq, t_ns, period):
        seq %= self.m
        st_ = self.state.get(key)
        if st_ is None:
            self.state[key] = [seq, seq, t_ns, {seq}]
            return SequenceEvent.FIRST, seq
        low, high, t_high, seen = st_
        advance = (t_ns - t_high) / period if (t_ns is not None and t_high is not None and period) else 0.0
        u = unwrap(seq, high, self.m, advance)
        if u < high - (self.w or self.m // 8):
            self.resets += 1
            self.state[key] = [seq, seq, t_ns, {seq}]
            return SequenceEvent.RESET, seq
        if self.w and u in seen:
            self.duplicates += 1
            return SequenceEvent.DUPLICATE, u
        seen.add(u)
        if u > high:
            if u > high + 1:
                self.gaps += 1
                self.lost += u - high - 1
            st_[1], st_[2] = u, t_ns
            return (SequenceEvent.IN_ORDER if u == high + 1 else SequenceEvent.GAP), u
        self.late += 1
        if u < low:
            self.lost += low - u - 1
            st_[0] = u
        else:
            self.lost -= 1
        return SequenceEvent.LATE, u


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2), st.one_of(st.integers(-6, 9), st.integers(-70, 300)), st.integers(0, 3),
                          st.booleans()),
                min_size=1, max_size=150),
       st.sampled_from([0, 1, 8, 40]), st.booleans(), st.integers(1, 5))
def test_tracker_equals_the_plain_reference_with_duplicates_late_frames_and_restarts(steps, window, timed, calls):
    """Numbers that step back (duplicates, late frames, restarts), repeat, skip and wrap, some with a time
    and some without, fed partly one by one and partly in batches: the same events, unwrapped numbers and
    counters as the plain set-based reference."""
    period = [MS, 4 * MS, 100 * MS]
    now = [0, 0, 0]
    codes, seqs, times = [], [], []
    for k, step, jitter, no_time in steps:
        now[k] = max(now[k] + step, 0)
        codes.append(k)
        seqs.append(now[k] % 256)
        times.append(-1 if (no_time or not timed) else (now[k] + jitter) * period[k])
    ref = ReferenceTracker(256, window)
    want = [ref.track(c, s, None if t < 0 else t, float(period[c])) for c, s, t in zip(codes, seqs, times)]
    got = SequenceTracker(256, window)
    events, unwrapped = [], []
    cuts = sorted({0, len(codes), *np.linspace(0, len(codes), calls + 1).astype(int).tolist()})
    for j, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        if j % 2:  # one by one, on the same keys: the two ways share one state
            for c, s, t in zip(codes[a:b], seqs[a:b], times[a:b]):
                e, u = got.track(c, s, None if t < 0 else t, float(period[c]))
                events.append(int(e))
                unwrapped.append(u)
        else:
            e, u = got.track_many(np.array(codes[a:b]), np.array(seqs[a:b]), int, np.array(times[a:b]),
                                  np.array(period, dtype=float)[codes[a:b]])
            events += e.tolist()
            unwrapped += u.tolist()
    assert events == [int(e) for e, _ in want]
    keep = [i for i, (e, _) in enumerate(want) if e != SequenceEvent.DUPLICATE]  # a duplicate's is meaningless
    assert [unwrapped[i] for i in keep] == [want[i][1] for i in keep]
    assert (got.gaps, got.lost, got.duplicates, got.late, got.resets) == \
        (ref.gaps, ref.lost, ref.duplicates, ref.late, ref.resets)


def test_unwrapper_follows_a_device_clock_across_wraps():
    u = Unwrapper(1 << 32)
    assert u(0xFFFF_FF00) == 0xFFFF_FF00
    assert u(0x10) == (1 << 32) + 0x10
    # 3 wraps of silence, told by the host time
    assert u(0x20, advance=3 * (1 << 32)) == 4 * (1 << 32) + 0x20


def test_bad_tracker_settings_are_refused():
    from tactile_descriptors_ros.errors import ConfigError

    with pytest.raises(ConfigError):
        SequenceTracker(16, window=8)


def test_stream_layer_imports_with_ros_blocked():
    code = textwrap.dedent(
        """
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in ('rclpy', 'rosidl_runtime_py', 'tactile_descriptors_msgs', 'std_msgs',
                                          'builtin_interfaces', 'launch', 'launch_ros'):
                    raise ImportError('blocked for this test: ' + name)
        sys.meta_path.insert(0, Block())
        from tactile_descriptors_ros.codecs import sequence
        from tactile_descriptors_ros.streams import biotac, frames, link, skin, skin_parts
        print('ok')
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_runs_of_a_batch_topic_count_lost_frames_and_restarts():
    from tactile_descriptors_ros.codecs.sequence import SequenceEvent

    t = SequenceTracker(1 << 32, window=0)
    assert t.track_run("a", 10, 5) == (SequenceEvent.FIRST, 0)  # frames 10..14
    assert t.track_run("a", 15, 5) == (SequenceEvent.IN_ORDER, 0)
    assert t.track_run("a", 23, 2) == (SequenceEvent.GAP, 3)  # 20, 21, 22 lost
    assert t.lost == 3 and t.gaps == 1
    # the 32-bit count wraps: no loss
    t.track_run("b", (1 << 32) - 2, 2)
    assert t.track_run("b", 0, 1) == (SequenceEvent.IN_ORDER, 0)
    # a sender that starts again from 0 is a restart, not four billion lost frames
    assert t.track_run("a", 0, 1) == (SequenceEvent.RESET, 0)
    assert t.resets == 1 and t.lost == 3
    with pytest.raises(Exception, match="window=0"):
        SequenceTracker(1 << 32, window=8).track_run("a", 0, 1)
