"""Every command block of the README and docs/ runs as written, so the docs cannot drift from the code.

A fenced block tagged ``bash`` is commands (the README's source
``.venv/setup.bash`` themselves, docs/ pages assume it); a block that shows commands as a
synopsis (``[--option]``) is tagged ``text``; an untagged block that starts with
a command fails :func:`test_command_blocks_are_tagged`.  Each ``bash`` block of
a page runs in order with ``bash -e`` in the checkout (files it writes are
removed afterwards), except those in :data:`SKIP` (each with its reason) and
pages whose commands another test runs (:data:`RUN_ELSEWHERE`).

A block whose command is ``ros2 launch`` or ``ros2 run`` keeps running, like a
terminal left open: it is started in its own process group, the following
blocks of the page run against it (a second terminal), and before the next such
block, or at the end of the page, it gets Ctrl-C (SIGINT to the group) and must
end with no traceback.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PAGES = ["README.md", *sorted(str(p.relative_to(REPO)) for p in (REPO / "docs").glob("*.md"))]
COMMAND_LANGS = {"bash", "sh", "shell", "console"}
#: The first line of an untagged block that shows a command.
COMMAND_START = re.compile(r"^(make|tactile|ros2|colcon|source|python3?|pip|\.venv/|[A-Z_]+=\S+ \S)\b")

#: (page, first line of the block) -> why it does not run here.
SKIP: dict[tuple[str, str], str] = {
    ("README.md", "make demo   # sets everything up, then a simulated Shadow Hand through the live node graph"):
        "`make test` is this test suite (it would run itself); the demo's graph is what "
        "test/launching/test_ros2_launch.py launches",
    ("README.md", "mkdir -p ~/ws/src && cd ~/ws/src && git clone <this repository> tactile_descriptors_ros"):
        "needs rosdep and a clone URL; test/packaging/test_colcon.py builds the same two packages "
        "with the same colcon command and launches from install/",
    ("docs/performance.md", "make bench                                  # full table (about 5 minutes)"):
        "minutes of benchmarking; test/perf/test_bench_command.py runs `tactile bench` on a small size",
    ("docs/latency.md", ".venv/bin/tactile bench --sizes 1000 --lengths 2 --latency --json > latency.json"):
        "a latency measurement of minutes; test/perf/test_latency.py measures a short one",
    ("docs/scaling.md", "tactile bench --scale-graph --cells 10000 --parts 20 --seconds 30 --json > scale_10000.json"):
        "41 processes for minutes; the page's small run above and test/perf/test_scale_graph.py run the same "
        "command on a small skin",
    ("docs/performance.md", "tactile bench --model-save"):
        "a benchmark of 100 durable saves of a 1,000-class model; test/perf/test_model_save_bench.py runs a small one",
    ("docs/simulator.md", "tactile fit-textures ../shared/data/biotac_slide_20_50 -o texture_models   "
                          "# fit the texture models (default ./texture_models)"):
        "fits all 20 materials of the real recordings (minutes) and rewrites the shipped models; "
        "test/sim/test_textures.py fits and checks them",
}
#: page -> the test that runs that page's command blocks with the files they need
RUN_ELSEWHERE = {"docs/import.md": "test/datasets/test_import_docs.py"}
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
        return any(re.match(r"ros2 (launch|run) ", line) for line in self.text.splitlines())

    def __str__(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(page: str) -> list[Block]:
    text = (REPO / page).read_text()
    out = []
    for m in re.finditer(r"^```(\w*)[^\n]*\n(.*?)^```", text, re.S | re.M):
        out.append(Block(page, text[:m.start()].count("\n") + 1, m.group(1), m.group(2)))
    return out


def _env(tmp: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("VIRTUAL_ENV", None)
    env["PATH"] = os.pathsep.join(p for p in env["PATH"].split(os.pathsep) if p)  # as a user's shell has it
    env["ROS_HOME"] = str(tmp / "ros_home")  # the classifier's model file goes here, not into ~/.ros
    env["HOME"] = str(tmp / "home")
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _sigint_default() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _untracked() -> set[str]:
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all", "--ignored=no"], cwd=REPO,
                         capture_output=True, text=True, check=True).stdout
    return {line[3:] for line in out.splitlines() if line.startswith("?? ")}


class Terminal:
    """A block that keeps running (``ros2 launch`` / ``ros2 run``), stopped with Ctrl-C."""

    def __init__(self, block: Block, env: dict[str, str], log: Path) -> None:
        self.block, self.log = block, log
        with open(log, "w") as fh:
            self.proc = subprocess.Popen(["bash", "-e", "-c", block.text], cwd=REPO, env=env, stdout=fh,
                                         stderr=subprocess.STDOUT, preexec_fn=_sigint_default,
                                         start_new_session=True)
        self.env = env
        self._wait_ready()

    def _wait_ready(self) -> None:
        """Until ``ros2 node list`` shows a node (the block has started its graph)."""
        ros2 = Path(sys.prefix) / "bin" / "ros2"
        deadline = time.monotonic() + READY_S
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, f"{self.block} ended early:\n{self.log.read_text()[-3000:]}"
            nodes = subprocess.run([str(ros2), "node", "list", "--no-daemon", "--spin-time", "2"], env=self.env,
                                   capture_output=True, text=True, timeout=60).stdout.split()
            if nodes:
                return
        raise AssertionError(f"{self.block}: no node came up:\n{self.log.read_text()[-3000:]}")

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
                                     f"{self.log.read_text()[-3000:]}")
        text = self.log.read_text(errors="replace")
        assert "Traceback" not in text and "escalating to" not in text, f"{self.block}:\n{text[-4000:]}"


def _in_venv(page: str, text: str) -> str:
    """The README's blocks source ``.venv/setup.bash`` themselves; docs/ pages assume it was sourced."""
    if page == "README.md":
        return text
    return f"source {Path(sys.prefix) / 'setup.bash'}\n{text}"


def test_command_blocks_are_tagged():
    untagged = [str(b) for page in PAGES for b in blocks(page)
                if not b.lang and COMMAND_START.match(b.first)]
    assert not untagged, f"tag these blocks `bash` (commands) or `text` (a synopsis): {untagged}"


def test_skip_list_names_existing_blocks():
    present = {(b.page, b.first) for page in PAGES for b in blocks(page)}
    assert set(SKIP) <= present, f"stale SKIP entries: {set(SKIP) - present}"
    for page, test in RUN_ELSEWHERE.items():
        assert (REPO / test).is_file(), f"{page}'s commands are said to run in {test}, which is missing"


@pytest.mark.ros
@pytest.mark.ros2cli
@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("page", [p for p in PAGES if p not in RUN_ELSEWHERE])
def test_page_commands_run(page, tmp_path):
    runnable = [b for b in blocks(page) if b.lang in COMMAND_LANGS and (page, b.first) not in SKIP]
    if not runnable:
        pytest.skip(f"{page} has no command block that runs here")
    env = _env(tmp_path)
    before = _untracked()
    terminal: Terminal | None = None
    try:
        for i, block in enumerate(runnable):
            if block.keeps_running:
                if terminal is not None:
                    terminal.stop()
                terminal = Terminal(Block(block.page, block.line, block.lang, _in_venv(page, block.text)), env,
                                    tmp_path / f"terminal_{i}.log")
                continue
            out = subprocess.run(["bash", "-e", "-c", _in_venv(page, block.text)], cwd=REPO, env=env, capture_output=True,
                                 text=True, timeout=BLOCK_S)
            assert out.returncode == 0, f"{block} exited {out.returncode}:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
            assert "Traceback" not in out.stderr, f"{block}:\n{out.stderr[-3000:]}"
        if terminal is not None:
            terminal.stop()
            terminal = None
    finally:
        if terminal is not None and terminal.proc.poll() is None:
            os.killpg(terminal.proc.pid, signal.SIGKILL)
            terminal.proc.wait()
        subprocess.run([str(Path(sys.prefix) / "bin" / "ros2"), "daemon", "stop"], env=env, capture_output=True,
                       timeout=60)
        for path in _untracked() - before:
            (REPO / path).unlink(missing_ok=True)
