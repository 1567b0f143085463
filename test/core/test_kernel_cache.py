"""The compiled kernel's cache does not depend on where the package is installed.

A copy of the kernel module at another path (as colcon's ``build/`` or
``install/`` makes) must load the code compiled at set-up instead of compiling
it again for about 30 s.  numba's dispatcher statistics tell a load (cache hit)
from a compilation (cache miss) without timing anything.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

numba = pytest.importorskip("numba")

_RUN = """
import importlib.util, json, sys
from tactile_descriptors_ros.core import fast
path = sys.argv[1]
if path != "-":  # the kernel module from another install path
    spec = importlib.util.spec_from_file_location("numba_kernel", path)
    kernel = importlib.util.module_from_spec(spec)
    sys.modules["numba_kernel"] = kernel
    spec.loader.exec_module(kernel)
    fast.BACKENDS["numba"] = "numba_kernel"  # the backend registry serves the copy
info = fast.warm_up()
kernel = fast.kernel_module()
stats = {name: (sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()))
         for name, f in vars(kernel).items() if hasattr(f, "stats") and hasattr(f.stats, "cache_hits")}
print(json.dumps({"accelerator": info["accelerator"], "file": kernel.__file__, "cache_dir": kernel.CACHE_DIR,
                  "path_independent": kernel.PATH_INDEPENDENT_CACHE, "stats": stats}))
"""


def _run(path: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _RUN, path], capture_output=True, text=True, timeout=240,
                         env={**__import__("os").environ, "TACTILE_NO_NUMBA": "0"})
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_copy_at_another_path_loads_the_compiled_kernel(tmp_path):
    here = _run("-")  # the installed kernel: loads what set-up compiled (or compiles it once)
    if here["accelerator"] != "numba":
        pytest.skip("numba is disabled")
    from tactile_descriptors_ros.core import numba_kernel

    copy = tmp_path / "install" / "lib" / "tactile_descriptors_ros" / "core" / "numba_kernel.py"
    copy.parent.mkdir(parents=True)
    shutil.copyfile(numba_kernel.__file__, copy)
    there = _run(str(copy))
    assert Path(there["file"]) == copy and there["path_independent"]
    assert there["cache_dir"] == here["cache_dir"]
    used = {name: s for name, s in there["stats"].items() if s != [0, 0]}
    assert used, "warm_up called no compiled function"
    misses = {name: s[1] for name, s in used.items() if s[1]}
    assert not misses, f"compiled again at the new path: {misses}"
