"""The view-overhead bench runs and reports what docs/view.md quotes (a short run: its figures are not checked)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_view_overhead_bench_reports_both_runs():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_lab.bench.view_overhead", "--seconds", "3",
                          "--warm", "5", "--json"], capture_output=True, text=True, timeout=540)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout)
    assert set(r["with_view"]["cpu_core_percent"]) == {"contact_node", "tactile_view"}
    assert set(r["without_view"]["cpu_core_percent"]) == {"contact_node"}
    assert r["view_overhead_percent"] == pytest.approx(r["contact_node_display_percent"] + r["tactile_view_percent"])
    assert r["with_view"]["page_frames"] > 0 and r["target_percent"] == 10.0
