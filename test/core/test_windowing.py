"""Fixed and exploration windows on sensor stamps, and counted stream faults."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.windowing import CellChunk, Windower, first_fixed_start
from tactile_descriptors_ros.errors import ConfigError

MS = 1_000_000


def _chunk(t0_ns: int, force_n: float, rng, n_frames: int = 10) -> CellChunk:
    """10 BioTac frames (100 ms) starting at t0."""
    frame_t = t0_ns + np.arange(n_frames, dtype=np.int64) * 10 * MS
    pac_t = (frame_t[:, None] + (np.arange(22) * 10 * MS) // 22).ravel()
    return CellChunk(rng.integers(0, 4096, (1, pac_t.size)), pac_t, rng.integers(0, 4096, (19, n_frames)),
                     frame_t, np.full(n_frames, force_n), frame_t)


def _grid_start(w: Windower) -> int:
    """The first fixed window's start for data from 0: a stream starting there is cut from its first sample."""
    return first_fixed_start(0, w.length_ns, w.hop_ns, w.grid_margin_ns)


def _feed(w: Windower, schedule, rng, cell_id: int = 1, t0_ns: int = 0):
    """schedule: list of (duration_s, force_n); returns windows emitted."""
    out, t = [], t0_ns
    for duration_s, force in schedule:
        for _ in range(int(round(duration_s * 10))):
            w.add(cell_id, _chunk(t, force, rng))
            out += w.poll()
            t += 100 * MS
    return out + w.flush()


def test_exploration_windows_run_from_onset_to_release():
    rng = np.random.default_rng(0)
    w = Windower(load_robot("shadow_hand"), mode="exploration")
    wins = _feed(w, [(1.0, 0.0), (3.0, 1.0), (1.0, 0.0), (2.5, 2.0), (1.0, 0.0)], rng)
    assert [x.exploration_id for x in wins] == [1, 2]
    assert (wins[0].end_ns - wins[0].start_ns) / 1e9 == pytest.approx(3.0, abs=0.02)
    assert wins[0].start_ns == 1000 * MS
    assert (wins[1].end_ns - wins[1].start_ns) / 1e9 == pytest.approx(2.5, abs=0.02)
    cell = wins[0].cells[1]
    assert cell.vibration.shape[1] == pytest.approx(3.0 * 2200, abs=25)
    # only the window's own samples: nothing from before the onset
    assert cell.deformation_t_ns[0] >= wins[0].start_ns and cell.vibration_t_ns[0] >= wins[0].start_ns


def test_exploration_too_short_is_dropped_and_counted_and_too_long_is_cut():
    rng = np.random.default_rng(1)
    w = Windower(load_robot("shadow_hand"), mode="exploration", min_duration_s=1.0, max_duration_s=2.0)
    wins = _feed(w, [(0.5, 0.0), (0.5, 1.0), (1.0, 0.0), (4.0, 1.0), (1.0, 0.0)], rng)
    assert w.faults["exploration_too_short"] == 1
    assert len(wins) == 1 and (wins[0].end_ns - wins[0].start_ns) == 2000 * MS
    assert wins[0].exploration_id == 2


def test_fixed_windows_have_length_and_hop():
    rng = np.random.default_rng(2)
    w = Windower(load_robot("shadow_hand"), mode="fixed", length_s=2.0, hop_s=0.5)
    wins = _feed(w, [(5.0, 1.0)], rng)
    starts = [x.start_ns for x in wins]
    assert np.all(np.diff(starts) == 500 * MS)
    assert all(x.end_ns - x.start_ns == 2000 * MS and x.exploration_id == 0 for x in wins)
    # ends 1.5 PAC periods before whole hops: the first complete window after the first sample at 0 ends then
    assert w.grid_margin_ns == round(1.5e9 / 2200)
    assert [x.end_ns for x in wins] == [k * 500 * MS - w.grid_margin_ns for k in range(5, 10)]
    first_pac = wins[0].cells[1].vibration_t_ns[0]
    assert 0 <= first_pac - wins[0].start_ns < 454_546  # the first PAC sample at or after the start


def test_fixed_windows_lie_on_one_grid_of_stamp_time_whenever_the_data_starts():
    """Two windowers fed the same stream from different first samples (a node started later, a bag replayed
    from its middle) cut the same windows where both have the data, to the same samples."""
    rng = np.random.default_rng(7)
    early = Windower(load_robot("shadow_hand"), mode="fixed", length_s=1.0, hop_s=0.3, lateness_s=0.0)
    late = Windower(load_robot("shadow_hand"), mode="fixed", length_s=1.0, hop_s=0.3, lateness_s=0.0)
    chunks = [_chunk(k * 100 * MS + 12_345, 1.0, rng) for k in range(50)]
    a, b = [], []
    for k, c in enumerate(chunks):
        early.add(1, c)
        a += early.poll()
        if k >= 17:
            late.add(1, c)
            b += late.poll()
    assert len(b) == 7 and b[0].start_ns >= chunks[17].vibration_t_ns[0] and len(a) > len(b)  # ends 3 .. 4.8 s
    same = {x.start_ns: x for x in a}
    for x in b:
        assert (x.end_ns + early.grid_margin_ns) % (300 * MS) == 0
        y = same[x.start_ns]
        assert np.array_equal(x.cells[1].vibration_t_ns, y.cells[1].vibration_t_ns)
        assert np.array_equal(x.cells[1].vibration, y.cells[1].vibration)


def test_a_new_hop_moves_the_next_window_onto_its_own_grid_never_back():
    rng = np.random.default_rng(8)
    w = Windower(load_robot("shadow_hand"), mode="fixed", length_s=1.0, hop_s=0.5, lateness_s=0.0)
    got = _feed(w, [(2.0, 1.0)], rng)  # data to 2 s: windows ending at 1.5 and 2 s - margin
    assert [x.end_ns for x in got] == [1500 * MS - w.grid_margin_ns, 2000 * MS - w.grid_margin_ns]
    w.retune(hop_s=0.4)
    got = _feed(w, [(2.0, 1.0)], rng, t0_ns=2000 * MS)
    # the window due next starts at 1.5 s - margin; the first on the 0.4 s grid not before it at 1.8 s - margin
    assert [x.end_ns for x in got] == [k * 400 * MS - w.grid_margin_ns for k in range(7, 11)]


def test_fixed_window_waits_for_every_live_cell_not_the_first_past_its_end():
    """Cells whose messages travel apart (one per body part): a window is cut once all of them passed its end."""
    rng = np.random.default_rng(5)
    w = Windower(load_robot("shadow_hand"), mode="fixed", length_s=1.0, hop_s=1.0, lateness_s=0.0)
    ahead, behind = 1, 2
    s = _grid_start(w)
    for t in range(0, 1000, 100):
        assert w.add(ahead, _chunk(s + t * MS, 1.0, rng)) and w.add(behind, _chunk(s + t * MS, 1.0, rng))
    assert w.poll() == []
    assert w.add(ahead, _chunk(s + 1000 * MS, 1.0, rng))  # one cell past the end of [s, s + 1 s)
    assert w.poll() == []  # the other cell's last samples of the window are still on their way
    assert w.add(behind, _chunk(s + 1000 * MS, 1.0, rng))
    (win,) = w.poll()
    assert (win.start_ns, win.end_ns) == (s, s + 1000 * MS) and set(win.cells) == {ahead, behind}
    assert not any(c.gap for c in win.cells.values()) and w.faults["gap"] == 0
    # a cell silent for longer than the stall time is not waited for
    for t in range(1100, 2700, 100):
        assert w.add(ahead, _chunk(s + t * MS, 1.0, rng))
    (win2,) = w.poll()
    assert win2.end_ns == s + 2000 * MS


def test_faults_are_counted_not_hidden():
    rng = np.random.default_rng(3)
    w = Windower(load_robot("shadow_hand"), mode="fixed")
    assert w.add(1, _chunk(0, 1.0, rng))
    assert not w.add(1, _chunk(0, 1.0, rng))  # duplicate stamps
    assert w.add(1, _chunk(100 * MS, 1.0, rng))
    assert not w.add(1, _chunk(50 * MS, 1.0, rng))  # out of order
    assert not w.add(77, _chunk(200 * MS, 1.0, rng))  # unknown cell
    bad = _chunk(200 * MS, 1.0, rng)
    bad.deformation = bad.deformation[:5]
    assert not w.add(1, bad)
    assert w.add(1, _chunk(200 * MS, 1.0, rng))
    assert w.add(1, _chunk(-5_000 * MS, 1.0, rng))  # clock jumped back 5 s: buffers reset
    assert dict(w.faults) == {"duplicate": 1, "out_of_order": 1, "unknown_cell": 1, "bad_shape": 1,
                              "clock_jump": 1}


def test_invalid_samples_are_removed_not_replaced_and_too_many_exclude_the_cell():
    rng = np.random.default_rng(4)
    w = Windower(load_robot("shadow_hand"), mode="fixed", length_s=1.0, hop_s=1.0)
    sent = {}
    for k in range(35):
        c = _chunk(_grid_start(w) + k * 100 * MS, 1.0, rng)
        if k == 3:  # one bad PAC word
            c.vibration_valid = np.ones(c.vibration.shape[1], bool)
            c.vibration_valid[5] = False
            sent["bad_t"] = c.vibration_t_ns[5]
        if 20 <= k < 25:  # half the frames of a window bad: more than 5 %
            c.vibration_valid = np.arange(c.vibration.shape[1]) % 2 == 0
        w.add(1, c)
    wins = w.poll()
    first, second, third = (x.cells[1] for x in wins[:3])
    assert first.valid and first.invalid_samples == 1
    assert first.vibration.shape[1] == 2200 - 1 and sent["bad_t"] not in first.vibration_t_ns
    assert second.valid and second.invalid_samples == 0
    assert not third.valid and third.invalid_samples == 550
    assert w.faults["windows_with_invalid_samples"] == 2


def test_bad_parameters_name_the_key():
    with pytest.raises(ConfigError, match="window.length_s"):
        Windower(load_robot("nao"), length_s=0.0)
    with pytest.raises(ConfigError, match="window.min_duration_s"):
        Windower(load_robot("nao"), min_duration_s=5.0, max_duration_s=2.0)


def test_onset_comes_from_the_cell_touching_now_not_an_older_touch():
    # Regression: the thumb's earlier touch used to set the onset of the
    # index finger's later exploration, stretching it back over no-contact time.
    rng = np.random.default_rng(5)
    w = Windower(load_robot("shadow_hand"), mode="exploration")
    wins, t = [], 0
    for k in range(80):
        thumb = 1.0 if 5 <= k < 25 else 0.0
        index = 1.0 if 45 <= k < 70 else 0.0
        w.add(0, _chunk(t, thumb, rng))
        w.add(1, _chunk(t, index, rng))
        wins += w.poll()
        t += 100 * MS
    assert [x.exploration_id for x in wins] == [1, 2]
    assert wins[0].start_ns == 500 * MS and wins[0].end_ns == pytest.approx(2500 * MS, abs=20 * MS)
    assert wins[1].start_ns == 4500 * MS and wins[1].end_ns == pytest.approx(7000 * MS, abs=20 * MS)


def test_release_is_judged_on_smoothed_force_not_single_noisy_samples():
    # Force hovering at 0.05 N with single samples spiking to 0.15 N (above the
    # 0.1 N release threshold) must still release.
    rng = np.random.default_rng(6)
    w = Windower(load_robot("shadow_hand"), mode="exploration")
    wins, t = [], 0
    for k in range(60):
        c = _chunk(t, 1.0 if 10 <= k < 30 else 0.05, rng)
        if k >= 30:
            c.force_n = c.force_n.copy()
            c.force_n[::7] = 0.15
        w.add(1, c)
        wins += w.poll()
        t += 100 * MS
    assert len(wins) == 1 and wins[0].end_ns == pytest.approx(3000 * MS, abs=20 * MS)


def _touches(rng) -> dict[int, list]:
    """Three fingers' 100 ms chunks over 6 s; each finger's touch starts and ends 10..70 ms apart."""
    onsets = {0: (1000, 3500), 1: (1010, 3560), 2: (1040, 3470)}  # ms: touch from, to
    out: dict[int, list] = {}
    for cid, (on, off) in onsets.items():
        chunks = []
        for k in range(60):
            t0 = k * 100 * MS
            frame_t = t0 + np.arange(10, dtype=np.int64) * 10 * MS
            force = np.where((frame_t >= on * MS) & (frame_t < off * MS), 1.5, 0.0)
            c = _chunk(t0, 0.0, rng)
            c.force_n = force
            chunks.append(c)
        out[cid] = chunks
    return out


def test_exploration_cut_does_not_depend_on_arrival_order_or_batching():
    """The same data, cells interleaved with different lags and batched differently: the same windows.

    A late finger that touched first moved the onset only when its data had arrived before the poll
    that saw contact (one frame, 10 ms, apart between runs); contact is now judged at the time every
    cell has reached.
    """
    robot = load_robot("shadow_hand")
    results = []
    for seed in range(6):
        order_rng = np.random.default_rng(seed)
        chunks = _touches(np.random.default_rng(99))
        lag = {cid: int(order_rng.integers(0, 300)) for cid in chunks}  # ms each finger's messages lag
        arrivals = sorted(((k * 100 + lag[cid] + int(order_rng.integers(0, 20)), cid, c)
                           for cid, cs in chunks.items() for k, c in enumerate(cs)), key=lambda a: (a[0], a[1]))
        w = Windower(robot, mode="exploration")
        wins, i = [], 0
        while i < len(arrivals):
            n = int(order_rng.integers(1, 1 + 8 * (seed % 3)) if seed % 3 else 1)
            w.add_many([(cid, c) for _, cid, c in arrivals[i:i + n]])
            wins += w.poll()
            i += n
        wins += w.flush()
        results.append([(x.exploration_id, x.start_ns, x.end_ns, sorted(x.cells)) for x in wins])
    assert results[0] == [(1, 1000 * MS, 3560 * MS, [0, 1, 2])]  # first touch to last release, every finger
    assert all(r == results[0] for r in results[1:]), results


def test_contact_held_past_max_duration_keeps_bounded_buffers():
    """A contact held for a minute (an object carried): after the window is cut at max_duration_s the
    buffers hold only the retained time, not every sample since the onset, and the release still ends
    the exploration."""
    rng = np.random.default_rng(5)
    w = Windower(load_robot("shadow_hand"), mode="exploration", max_duration_s=2.0)
    sizes = []
    t = 0
    wins = []
    for k in range(600):  # 60 s at 2 N
        w.add(1, _chunk(t, 2.0, rng))
        wins += w.poll()
        t += 100 * MS
        if k % 50 == 49:
            sizes.append(len(w._cells[1].vib))
    retained_s = (w._retain_ns + 100 * MS) / 1e9
    assert max(sizes) <= retained_s * 2200 + 22 * 10, sizes  # bounded by the retained time, not growing
    assert sizes[-1] == sizes[-3]
    assert len(wins) == 1 and (wins[0].end_ns - wins[0].start_ns) == 2000 * MS
    for _ in range(10):  # release: the exploration ends and the next touch is a new one
        w.add(1, _chunk(t, 0.0, rng))
        wins += w.poll()
        t += 100 * MS
    wins += _feed_from(w, t, [(3.0, 2.0), (1.0, 0.0)], rng)
    assert [x.exploration_id for x in wins] == [1, 2]


def test_buffers_are_sized_from_the_robot_description_and_never_grow():
    """A cell's buffers are sized at its first chunk from its cell type's rates and the longest span the
    windower keeps: over a minute of touches, releases and a contact held past max_duration_s (in chunks
    of 0.1 s and in a burst of 2 s) they are never reallocated, and they hold at most the headroom over
    the data they keep (doubling left buffers of 2-4 times it, growing for minutes)."""
    from tactile_descriptors_ros.core.windowing import BUFFER_HEADROOM, BUFFER_SLACK_S

    rng = np.random.default_rng(6)
    robot = load_robot("shadow_hand")
    w = Windower(robot, mode="exploration", max_duration_s=2.0)
    w.add(1, _chunk(0, 0.0, rng))
    st = w._cells[1]
    streams = (st.vib, st.dfm, st.force, st.extra)
    arrays = [s.buf.v for s in streams]
    span_s = w._retain_ns / 1e9 + BUFFER_SLACK_S
    ct = robot.cell_types[robot.cell_index()[1][0].cell_type]
    assert st.vib.capacity == int(np.ceil(BUFFER_HEADROOM * span_s * ct.vibration.rate_hz))
    assert st.dfm.capacity == int(np.ceil(BUFFER_HEADROOM * span_s * ct.deformation.rate_hz))
    assert st.force.capacity == int(np.ceil(BUFFER_HEADROOM * span_s * ct.force.rate_hz))
    assert w.buffer_bytes == sum(s.nbytes for s in streams)
    t, wins, kept = 100 * MS, [], []
    schedule = [(1.0, 0.0), (3.0, 2.0), (0.5, 0.0), (30.0, 2.0), (1.0, 0.0), (2.0, 1.0), (20.0, 0.0)]
    for duration_s, force in schedule:
        for _ in range(int(round(duration_s * 10))):
            w.add(1, _chunk(t, force, rng))
            wins += w.poll()
            t += 100 * MS
            kept.append(len(st.vib))
    burst = []
    for _ in range(20):  # a node catching up: 2 s of chunks in one batch
        burst.append((1, _chunk(t, 2.0, rng)))
        t += 100 * MS
    w.add_many(burst)
    wins += w.poll()
    assert all(s.buf.v is a for s, a in zip(streams, arrays))  # never reallocated
    # sized for what is kept (plus the slack and a chunk), not 2-4 times it
    assert st.vib.capacity <= BUFFER_HEADROOM * (max(kept) + (BUFFER_SLACK_S + 0.1) * ct.vibration.rate_hz)
    assert [x.exploration_id for x in wins] == [1, 2, 3]


def _feed_from(w: Windower, t: int, schedule, rng, cell_id: int = 1):
    out = []
    for duration_s, force in schedule:
        for _ in range(int(round(duration_s * 10))):
            w.add(cell_id, _chunk(t, force, rng))
            out += w.poll()
            t += 100 * MS
    return out + w.flush()


@pytest.mark.parametrize("batch", [1, 3, 7, 1000])
def test_exploration_windows_do_not_depend_on_how_many_chunks_a_poll_sees(batch):
    """Polling after every chunk or after a burst of them (a node catching up, a replay without pacing) gives
    the same windows: a whole touch, a release and a short re-touch inside one burst are all seen."""
    robot = load_robot("shadow_hand")
    schedule = [(1.0, 0.0), (3.0, 1.0), (0.5, 0.0), (0.2, 1.0), (0.3, 0.0), (2.5, 2.0), (1.0, 0.0),
                (12.0, 1.0), (1.0, 0.0)]
    rng = np.random.default_rng(4)
    chunks, t = [], 0
    for duration_s, force in schedule:
        for _ in range(int(round(duration_s * 10))):
            chunks.append(_chunk(t, force, rng))
            t += 100 * MS
    w = Windower(robot, mode="exploration", min_duration_s=0.1, max_duration_s=10.0)
    wins = []
    for k in range(0, len(chunks), batch):
        w.add_many([(1, c) for c in chunks[k:k + batch]])
        wins += w.poll()
    wins += w.flush()
    got = [(x.exploration_id, x.start_ns // MS, x.end_ns // MS) for x in wins]
    # touch 1.0-4.0 s, re-touch 4.5-4.7 s, touch 5.0-7.5 s, 8.5 s onwards cut at the longest duration
    assert got == [(1, 1000, 4000), (2, 4500, 4700), (3, 5000, 7500), (4, 8500, 18500)]


def test_a_cell_that_joins_without_moving_the_watermark_is_judged_at_that_poll():
    """A poll whose watermark has not moved skips the state machine only when the live cells are the same.

    Cell 0 has sent no force up to 990 ms; cell 1 starts sending at 900 ms, pressing, with samples past the
    watermark, so the watermark (the slowest live cell's newest stamp) stays at 990 ms while the live cells
    change: the onset at 900 ms must be decided at this poll, not one message later.
    """
    rng = np.random.default_rng(0)
    w = Windower(load_robot("shadow_hand"), mode="exploration")
    wins = []
    for k in range(10):
        w.add(0, _chunk(k * 100 * MS, 0.0, rng))
        wins += w.poll()
    assert w._watermark() == 990 * MS and not w.in_contact
    w.add(1, _chunk(900 * MS, 2.0, rng))
    wins += w.poll()
    assert w._watermark() == 990 * MS
    assert w.in_contact
    for k in range(10, 40):
        w.add(0, _chunk(k * 100 * MS, 0.0, rng))
        w.add(1, _chunk((k + 9) * 100 * MS, 2.0 if k < 25 else 0.0, rng))
        wins += w.poll()
    wins += w.flush()
    assert [(x.start_ns, x.exploration_id) for x in wins] == [(900 * MS, 1)]
