"""The stacks of a process a test waited on in vain, for its failure message (``py-spy dump --native``).

A node that does not end after its signal is stuck in a call that never returns; where that call is
native (rcl, Fast DDS), Python's fault handler shows only the Python line that made it.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

#: py-spy, installed with the test requirements.
PY_SPY = Path(sys.prefix) / "bin" / "py-spy"
#: Longest a dump may take [s] (it pauses the process it reads).
DUMP_S = 60.0


def native_stacks(pid: int) -> str:
    """Every thread's Python and native stack of process ``pid``, or why there are none."""
    if not PY_SPY.is_file():
        return f"(no stacks: {PY_SPY} is missing)"
    try:
        out = subprocess.run([str(PY_SPY), "dump", "--native", "--pid", str(pid)], capture_output=True, text=True,
                             timeout=DUMP_S)
    except subprocess.TimeoutExpired:
        return f"(no stacks: py-spy took more than {DUMP_S:.0f} s)"
    return out.stdout + out.stderr
