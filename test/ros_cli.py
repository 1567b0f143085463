"""Running the ``ros2`` CLI from tests the way a user does: a call that overruns is stopped with Ctrl-C.

A ``ros2`` process is a DDS participant.  Killed outright (``subprocess.run``'s timeout sends SIGKILL) it
cannot release its Fast DDS shared-memory port, and a lock taken in that port stays taken for every later
participant that opens it.  So an overrun call gets SIGINT first, as a user's Ctrl-C, and SIGKILL only if it
is still there :data:`STOP_S` later.
"""

from __future__ import annotations

import os
import pty
import re
import signal
import subprocess
import sys
import weakref
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ROS2", "STOP_S", "CliRun", "finish", "run_ros2", "start_at_a_terminal", "without_launchs_ignored_interrupt"]

#: The venv's ``ros2`` (the real CLI, built from upstream sources by the Makefile).
ROS2 = Path(sys.prefix) / "bin" / "ros2"
#: How long a call stopped with Ctrl-C may take to end before it is killed [s].
STOP_S = 60.0


@dataclass(frozen=True)
class CliRun:
    """What one ``ros2`` call did."""

    #: The exit status; after a Ctrl-C, what the CLI returned for it (-9 when it had to be killed).
    returncode: int
    stdout: str
    stderr: str
    #: Whether the call overran its time and was stopped (Ctrl-C, then SIGKILL after :data:`STOP_S`).
    stopped: bool

    @property
    def text(self) -> str:
        return self.stdout + self.stderr

    @property
    def crashed(self) -> bool:
        """Ended by a signal the caller did not send (not stopped, yet a negative status)."""
        return self.returncode < 0 and not self.stopped


def finish(proc: subprocess.Popen, timeout_s: float) -> CliRun:
    """Wait for a started call (text pipes) for ``timeout_s``; stop it with Ctrl-C if it overruns."""
    try:
        out, err = proc.communicate(timeout=timeout_s)
        return CliRun(proc.returncode, out, err, stopped=False)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=STOP_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return CliRun(proc.returncode, out or "", err or "", stopped=True)


def run_ros2(*args: str, env: dict[str, str], timeout_s: float) -> CliRun:
    """Run ``ros2 ARGS`` for at most ``timeout_s`` (then Ctrl-C, see :func:`finish`)."""
    proc = subprocess.Popen([str(ROS2), *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return finish(proc, timeout_s)


#: ``ros2 launch`` takes Ctrl-C as a ``KeyboardInterrupt`` that its run loop catches and ignores (its own
#: handler then stops the nodes).  When the signal lands while Python runs a callback it cannot raise
#: from (a weak reference's, during garbage collection), Python prints the interrupt as "Exception
#: ignored in: ..." with its traceback and goes on; the launch then stops as always.  Such a block is
#: the launch process's own: it is not prefixed with a node's ``[name-N]`` as everything a node prints
#: is, and its exception is ``KeyboardInterrupt`` and nothing else.
_LAUNCHS_IGNORED_INTERRUPT = re.compile(
    r"^Exception ignored in: [^\n]*\nTraceback \(most recent call last\):\n(?:(?: [^\n]*)?\n)*?KeyboardInterrupt: ?\n",
    re.M)


def without_launchs_ignored_interrupt(text: str) -> str:
    """``ros2 launch``'s output without the launch process's own ignored ``KeyboardInterrupt`` after a Ctrl-C
    (:data:`_LAUNCHS_IGNORED_INTERRUPT`): what is left shows every traceback a node printed."""
    return _LAUNCHS_IGNORED_INTERRUPT.sub("", text)


def start_at_a_terminal(cmd: list[str], log: Path, **kwargs) -> subprocess.Popen:
    """Start ``cmd`` as a user does at a terminal: a process group of its own (a Ctrl-C is SIGINT to the
    group, ``os.killpg``), a terminal on stdin, its output in ``log``; ``kwargs`` go to ``subprocess.Popen``.

    ``ros2 launch`` looks at stdin: when it is not a terminal it runs "noninteractive" and on SIGINT also
    signals every node itself.  After a Ctrl-C to the group a node then gets a second SIGINT from launch,
    and if it has ended already, asyncio's ``send_signal`` (``subprocess.Popen.send_signal`` polls first)
    reaps it under launch's child watcher, which then reports "Unknown child process" and launch "process
    has died [... exit code 255]" for a node that ended cleanly.  At a terminal launch leaves the SIGINT to
    the terminal, as it does here.
    """
    master, slave = pty.openpty()
    try:
        with open(log, "w") as fh:
            proc = subprocess.Popen(cmd, stdin=slave, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True,
                                    **kwargs)
    except BaseException:
        os.close(master)
        raise
    finally:
        os.close(slave)
    weakref.finalize(proc, os.close, master)  # the terminal stays open while anything holds the process
    return proc
