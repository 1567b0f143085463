"""SampleStream (the windower's per-cell buffer) behaves like a plain list model.

Its internals were made cheaper per message (cached last stamp, trims that
skip the search, in-place compaction); any sequence of appends, trims and
clears must still give the samples a list would.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core.windowing import SampleStream
from tactile_descriptors_ros.errors import SignalError

ops = st.lists(
    st.one_of(
        st.tuples(st.just("append"), st.integers(0, 300), st.booleans()),
        st.tuples(st.just("trim"), st.integers(-50, 400), st.just(False)),
        st.tuples(st.just("clear"), st.just(0), st.just(False)),
    ),
    max_size=60,
)


@settings(max_examples=100, deadline=None)
@given(ops, st.integers(1, 3))
def test_sample_stream_matches_a_list_model(sequence, n_channels):
    stream = SampleStream(n_channels, np.int32)
    model: list[tuple[int, tuple[int, ...], bool]] = []
    t_next = 0
    for op, arg, flag in sequence:
        if op == "append":
            t = np.arange(t_next, t_next + arg, dtype=np.int64)
            vals = (np.arange(n_channels)[:, None] * 1000 + t[None, :] % 997).astype(np.int32)
            valid = (t % 3 != 0) if flag else None
            stream.append(t, vals, valid)
            model += [(int(t[i]), tuple(vals[:, i]), True if valid is None else bool(valid[i])) for i in range(arg)]
            t_next += arg
        elif op == "trim":
            cut = t_next - arg
            keep_from = next((i for i, m in enumerate(model) if m[0] >= cut), len(model))
            model = model[keep_from:]
            stream.trim_before(cut)
        else:
            stream.clear()
            model = []
        assert len(stream) == len(model)
        assert stream.last_t_ns == (model[-1][0] if model else None)
        t, v, ok = stream.between(-(10**9), 10**9)
        assert t.tolist() == [m[0] for m in model]
        assert [tuple(col) for col in v.T.tolist()] == [m[1] for m in model]
        assert ok.tolist() == [m[2] for m in model]


def test_sample_stream_rejects_wrong_shapes():
    stream = SampleStream(2, np.int16)
    with pytest.raises(SignalError):
        stream.append(np.arange(3), np.zeros((3, 3), dtype=np.int16))
