"""Command blocks of markdown pages, run as a user would type them (shared by the robot's and the lab's doc tests).

A fenced block tagged ``bash`` is commands (the READMEs source
``.venv/setup.bash`` themselves, pages under docs/ assume it); a block that
shows commands as a synopsis (``[--option]``) is tagged ``text``.  Each
``bash`` block of a page runs in order with ``bash -e`` in the checkout (files
it writes are removed afterwards), except those a page's test skips with a
reason.

A block whose command is ``ros2 launch`` or ``ros2 run`` keeps running, like a
terminal left open: it is started in its own process group, the following
blocks of the page run against it (a second terminal), and before the next such
block, or at the end of the page, it gets Ctrl-C (SIGINT to the group) and must
end with no traceback.

A block that serves until Ctrl-C (``tactile view`` without ``--snapshot``)
runs beside the graph the same way (a third terminal): it is ready when it
has printed its address and that address answers with the page; the blocks
after it run while it serves, and it gets Ctrl-C before the graph does (at
the next block that keeps running, or at the end of the page).  It serves on
a free port the runner names in ``TACTILE_VIEW_PORT``, so two runs on one
machine do not collide on the documented default.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest
from ros_cli import run_ros2, start_at_a_terminal, without_launchs_ignored_interrupt

REPO = Path(__file__).resolve().parents[1]
COMMAND_LANGS = {"bash", "sh", "shell", "console"}
#: The first line of an untagged block that shows a command.
COMMAND_START = re.compile(r"^(make|tactile|ros2|colcon|source|python3?|pip|\.venv/|[A-Z_]+=\S+ \S)\b")
#: A command that keeps serving a page until Ctrl-C (a snapshot writes a file and ends).
SERVES = re.compile(r"^tactile view\b(?!.*--snapshot)")
#: What a serving command prints when it is up (``tactile view: http://127.0.0.1:8765/ (...)``).
SERVING_URL = re.compile(r"(http://[^\s/]+/)")
#: bounds that stop a hung block (a loaded 2-core machine): they measure nothing
BLOCK_S = 300.0
READY_S = 240.0
STOP_S = 20.0


@dataclass
class Block:
    page: str
    line: int
    lang: str
    text: str

    @property
    def first(self) -> str:
        return self.text.strip().splitlines()[0] if self.text.strip() else ""

    @property
    def keeps_running(self) -> bool:
        """A graph: ``ros2 launch`` or ``ros2 run``."""
        return any(re.match(r"ros2 (launch|run) ", line) for line in self.text.splitlines())

    @property
    def serves(self) -> bool:
        """A server beside the graph (:data:`SERVES`)."""
        return any(SERVES.match(line) for line in self.text.splitlines())

    def __str__(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(page: str) -> list[Block]:
    text = (REPO / page).read_text()
    out = []
    for m in re.finditer(r"^```(\w*)[^\n]*\n(.*?)^```", text, re.S | re.M):
        out.append(Block(page, text[:m.start()].count("\n") + 1, m.group(1), m.group(2)))
    return out


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(tmp: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("VIRTUAL_ENV", None)
    env["PATH"] = os.pathsep.join(p for p in env["PATH"].split(os.pathsep) if p)  # as a user's shell has it
    env["ROS_HOME"] = str(tmp / "ros_home")  # the classifier's model file goes here, not into ~/.ros
    env["HOME"] = str(tmp / "home")
    env["PYTHONUNBUFFERED"] = "1"
    env["TACTILE_VIEW_PORT"] = str(_free_port())  # tactile view's default port, one per run
    return env



def _untracked() -> set[str]:
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all", "--ignored=no"], cwd=REPO,
                         capture_output=True, text=True, check=True).stdout
    return {line[3:] for line in out.splitlines() if line.startswith("?? ")}


class Terminal:
    """A block that keeps running (``ros2 launch`` / ``ros2 run``), stopped with Ctrl-C."""

    what = "no node came up"

    def __init__(self, block: Block, env: dict[str, str], log: Path) -> None:
        self.block, self.log = block, log
        self.proc = start_at_a_terminal(["bash", "-e", "-c", block.text], log, cwd=REPO, env=env)
        self.env = env
        try:
            self._wait_ready()
        except BaseException:
            self.kill()
            raise

    def kill(self) -> None:
        """End the block's process group at once (a block that failed, or a test that did)."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def _wait_ready(self) -> None:
        """Until ``ros2 node list`` shows a node (the block has started its graph), and the ``ros2`` daemon,
        which the page's next commands ask (they give one second to find a node), lists it too."""
        deadline = time.monotonic() + READY_S
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, f"{self.block} ended early:\n{self.log.read_text()[-3000:]}"
            nodes = run_ros2("node", "list", "--no-daemon", "--spin-time", "2", env=self.env, timeout_s=60).stdout
            if nodes.split():
                daemons = run_ros2("node", "list", env=self.env, timeout_s=60).stdout
                if set(nodes.split()) <= set(daemons.split()):
                    return
        raise AssertionError(f"{self.block}: {self.what}:\n{self.log.read_text()[-3000:]}")

    def stop(self) -> None:
        """Ctrl-C; it must end, without a traceback."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=STOP_S)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
                raise AssertionError(f"{self.block} still running {STOP_S} s after Ctrl-C:\n"
                                     f"{self.log.read_text()[-3000:]}") from None
        text = self.log.read_text(errors="replace")
        # ros2 launch's own ignored interrupt is left out (see the function); anything else's is a failure
        launches = re.search(r"^ros2 launch ", self.block.text, re.M) is not None
        nodes_text = without_launchs_ignored_interrupt(text) if launches else text
        assert "Traceback" not in nodes_text and "escalating to" not in text, f"{self.block}:\n{text[-4000:]}"


class Server(Terminal):
    """A block that serves a page until Ctrl-C (:data:`SERVES`), beside a graph."""

    what = "no page served"

    def _wait_ready(self) -> None:
        """Until it has printed its address and the address answers with a page."""
        deadline = time.monotonic() + READY_S
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, f"{self.block} ended early:\n{self.log.read_text()[-3000:]}"
            m = SERVING_URL.search(self.log.read_text(errors="replace"))
            if m is None:
                time.sleep(0.2)  # the log file has no event to wait on; the address appears once
                continue
            try:
                with urllib.request.urlopen(m.group(1), timeout=30) as r:
                    page = r.read()
            except (urllib.error.URLError, OSError) as exc:
                raise AssertionError(f"{self.block}: {m.group(1)} does not answer: {exc}") from None
            assert r.status == 200 and b"<html" in page.lower(), f"{self.block}: {m.group(1)} served {page[:200]!r}"
            self.url = m.group(1)
            return
        raise AssertionError(f"{self.block}: {self.what}:\n{self.log.read_text()[-3000:]}")


def _in_venv(page: str, text: str) -> str:
    """The READMEs' blocks source ``.venv/setup.bash`` themselves; pages under docs/ assume it was sourced."""
    if page.endswith("README.md"):
        return text
    return f"source {Path(sys.prefix) / 'setup.bash'}\n{text}"




def untagged_command_blocks(pages: list[str]) -> list[str]:
    """Blocks that show a command but are tagged neither ``bash`` nor ``text``."""
    return [str(b) for page in pages for b in blocks(page) if not b.lang and COMMAND_START.match(b.first)]


def run_page(page: str, skip: dict[tuple[str, str], str], tmp_path: Path) -> None:
    """Run every command block of ``page`` but those in ``skip`` (page, first line) -> reason."""
    runnable = [b for b in blocks(page) if b.lang in COMMAND_LANGS and (page, b.first) not in skip]
    if not runnable:
        pytest.skip(f"{page} has no command block that runs here")
    env = _env(tmp_path)
    before = _untracked()
    terminals: list[Terminal] = []  # the graph first, a server beside it after

    def stop_all() -> None:
        while terminals:
            terminals.pop().stop()  # the server before the graph it shows

    try:
        for i, block in enumerate(runnable):
            if block.keeps_running or block.serves:
                if block.keeps_running:
                    stop_all()
                else:
                    while terminals and isinstance(terminals[-1], Server):
                        terminals.pop().stop()
                kind = Terminal if block.keeps_running else Server
                terminals.append(kind(Block(block.page, block.line, block.lang, _in_venv(page, block.text)), env,
                                      tmp_path / f"terminal_{i}.log"))
                continue
            out = subprocess.run(["bash", "-e", "-c", _in_venv(page, block.text)], cwd=REPO, env=env, capture_output=True,
                                 text=True, timeout=BLOCK_S)
            assert out.returncode == 0, f"{block} exited {out.returncode}:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
            assert "Traceback" not in out.stderr, f"{block}:\n{out.stderr[-3000:]}"
        stop_all()
    finally:
        for terminal in reversed(terminals):
            terminal.kill()
        subprocess.run([str(Path(sys.prefix) / "bin" / "ros2"), "daemon", "stop"], env=env, capture_output=True,
                       timeout=60)
        for path in _untracked() - before:
            (REPO / path).unlink(missing_ok=True)
