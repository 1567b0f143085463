"""Fast DDS's shared-memory files of dead participants (the root ``conftest.py`` removes them per test module)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

#: Fast DDS's own tool (shipped with its wheel): ``fastdds shm clean``.
FASTDDS_TOOL = Path(sys.prefix) / "tools" / "fastdds" / "fastdds.py"


def clean_zombie_shm() -> None:
    """Remove the shared-memory ports and segments of Fast DDS participants that died without closing them.

    ``fastdds shm clean`` removes only files that no live process holds a lock on, so concurrent runs keep
    theirs.  Tests kill nodes on purpose (SIGKILL) and leave such files behind (about 900 after a few runs
    of the suite); Fast DDS reopens a dead participant's port when a new participant gets its number, and a
    port left half-written can crash that participant (a ``ros2`` CLI call, a node) as it starts.
    """
    if FASTDDS_TOOL.is_file():
        subprocess.run([sys.executable, str(FASTDDS_TOOL), "shm", "clean"], capture_output=True, timeout=60)
