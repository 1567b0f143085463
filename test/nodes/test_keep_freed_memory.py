"""``keep_freed_memory``: a process that allocates and frees a window's arrays over and over reuses its pages.

Counted, not timed: the page faults of the process (``ru_minflt``) while it allocates, fills and frees
arrays of a NAO window's sizes, with glibc's default thresholds and with the node's.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

from tactile_descriptors_ros.nodes import common

_LOOP = r"""
import resource, sys
import numpy as np
from tactile_descriptors_ros.nodes.common import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "keep" else False
shapes = [((116, 3, 2000), np.int32), ((116, 2000), np.int64), ((116, 3, 500), np.int32), ((116, 500), np.int64),
          ((116, 500), np.float64), ((116, 2, 500), np.float64)]  # a NAO window's stacks: about 7 MB
def window():
    arrays = [np.empty(shape, dtype) for shape, dtype in shapes]
    for a in arrays:
        a.fill(1)
for _ in range(5):
    window()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(40):
    window()
print(kept, (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 40)
"""


def _faults_per_window(mode: str) -> tuple[bool, float]:
    env = {k: v for k, v in os.environ.items() if k not in common.MALLOC_ENV}
    out = subprocess.run([sys.executable, "-c", _LOOP, mode], env=env, capture_output=True, text=True, timeout=120,
                         check=True).stdout.split()
    return out[0] == "True", float(out[1])


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt thresholds are glibc's")
def test_a_window_freed_and_allocated_again_reuses_its_pages():
    kept, with_keep = _faults_per_window("keep")
    _, default = _faults_per_window("default")
    assert kept
    # 7 MB is about 1,800 pages: with glibc's defaults most of them are faulted in again for every window
    assert default > 1_000, default
    assert with_keep < default / 10, (with_keep, default)


def test_the_users_thresholds_stand(monkeypatch):
    calls = []

    class NoLibc:
        def __init__(self, name):
            calls.append(name)

    monkeypatch.setattr("ctypes.CDLL", NoLibc)
    for name in common.MALLOC_ENV:
        monkeypatch.setenv(name, "1")
        assert common.keep_freed_memory() is False
        monkeypatch.delenv(name)
    assert calls == []  # the allocator was not touched
