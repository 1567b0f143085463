"""``tactile bench --view-overhead``: runs with and without the views, alternating, and the overhead from them."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tactile_descriptors_lab.bench.view_overhead import TARGET_PERCENT, format_view_overhead


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(900)
def test_view_overhead_bench_runs_the_contact_node_with_and_without_the_views():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--view-overhead",
                          "--rounds", "1", "--seconds", "3", "--settle-s", "1", "--json"],
                         capture_output=True, text=True, timeout=800)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout)
    assert [run["display"] for run in r["runs"]] == [False, True]  # round 1: without, then with
    off, on = r["runs"]
    assert set(off["cpu_core_percent"]) == {"contact_node"}
    assert set(on["cpu_core_percent"]) == {"contact_node", "tactile_view"}
    assert on["page_frames"] > 0 and off["page_frames"] == 0  # the page read frames while it was measured
    for run in r["runs"]:  # the probe offered frames and the contact node answered them
        assert run["probe_messages_per_s"] > 0 and run["contacts_per_s"] is not None and run["contacts_per_s"] > 0
    # the display at full rate from the node's own count: 10 ticks and 700 messages a second
    assert on["display_tick_cpu_ms"] > 0 and on["display_merge_cpu_us"] > 0 and on["display_ticks_per_s"] > 0
    assert r["contact_node_display_percent"] == pytest.approx(
        (on["display_tick_cpu_ms"] * 10 + on["display_merge_cpu_us"] * 1e-3 * 700) / 10)
    assert r["contact_node_display_difference_percent"] == pytest.approx(
        on["cpu_core_percent"]["contact_node"] - off["cpu_core_percent"]["contact_node"])
    # tactile view at full rate: its CPU per frame it published, 10 frames a second
    assert on["view_frames_per_s"] > 0 and r["tactile_view_percent"] == pytest.approx(on["view_cpu_ms_per_frame"])
    assert r["view_overhead_percent"] == pytest.approx(r["contact_node_display_percent"] + r["tactile_view_percent"])
    assert r["met"] == (r["view_overhead_percent"] < TARGET_PERCENT) and r["full_rate_messages_per_s"] == 700
    assert "overhead" in format_view_overhead(r)


def test_a_bad_count_of_rounds_is_refused():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--view-overhead",
                          "--rounds", "0"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "--rounds and --seconds must be positive" in out.stderr
