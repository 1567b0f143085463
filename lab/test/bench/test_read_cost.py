"""``tactile bench --read-cost``: the skin driver's read path, compiled against numpy, checked equal first."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tactile_descriptors_lab.bench.read_cost import read_cost
from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder
from tactile_descriptors_ros.core import fast
from tactile_descriptors_ros.sim.synthetic import cell_samples_per_s

pytestmark = pytest.mark.skipif(fast.kernel_module() is None, reason="the compiled backend is not loaded here")


@pytest.mark.parametrize("stamps", ["device", "clock"])
def test_bench_read_cost_times_every_path_of_the_same_reads(stamps):
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--read-cost",
                          "--read-cost-cells", "20", "--rounds", "1", "--read-cost-stamps", stamps, "--json"],
                         capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    r = json.loads(out.stdout)
    assert r["same_messages"] is True and r["cells"] == 20 and r["stamp_source"] == stamps
    assert r["read_period_s"] == 0.005 and r["batch_s"] == 0.01  # the NAO graph's drivers
    assert r["reads"] == 800 and r["messages"] == 400  # 4 s read every 5 ms, a message every 10 ms
    assert r["frames"] == pytest.approx(20 * cell_samples_per_s() * 4.0, rel=0.01)
    for path in ("compiled", "without_stamping", "numpy"):
        assert r["ms_per_read"][path] > 0
        assert r["ms_per_cell_second"][path] == pytest.approx(r["ms_per_read"][path] / (20 * 0.005))
    assert r["speedup"] == pytest.approx(r["ms_per_read"]["numpy"] / r["ms_per_read"]["compiled"])
    assert r["stamping_speedup"] == pytest.approx(r["ms_per_read"]["without_stamping"] / r["ms_per_read"]["compiled"])


def test_read_cost_of_several_body_parts_builds_a_message_per_part_and_batch():
    """The NAO's cells make 7 body parts on one bus: a message each per batch, both paths the same."""
    r = read_cost(21, parts=3, seconds=1.0, repeat=1)
    assert r["same_messages"] is True and (r["cells"], r["parts"]) == (21, 3)
    assert r["reads"] == 200 and r["messages"] == 3 * 100


def test_read_cost_times_nothing_when_the_paths_disagree(monkeypatch):
    compiled = SkinCanDecoder._decode_compiled

    def one_sample_short(self, kernel, frames, arrival_ns):  # the compiled path loses each read's last frame
        return compiled(self, kernel, frames[:-1], arrival_ns)

    monkeypatch.setattr(SkinCanDecoder, "_decode_compiled", one_sample_short)
    with pytest.raises(RuntimeError, match="disagree"):
        read_cost(10, seconds=0.5, repeat=1)


def test_read_cost_times_nothing_when_the_stamping_disagrees(monkeypatch):
    """The compiled stamping is checked against numpy's before anything is timed, with either stamps."""
    from tactile_descriptors_ros.streams.skin import SkinStream

    compiled = SkinStream._add_compiled

    def one_late(self, kernel, ks, useq, starts, ends, vals, t):  # each read's stamps given 1 ns late
        return compiled(self, kernel, ks, useq, starts, ends, vals, None if t is None else t + 1)

    monkeypatch.setattr(SkinStream, "_add_compiled", one_late)
    with pytest.raises(RuntimeError, match="the compiled and numpy read paths disagree"):
        read_cost(10, seconds=0.5, repeat=1)
