"""Every command block of the lab's README and pages runs as written (see ``test/doc_blocks.py``)."""

from __future__ import annotations

import pytest
from doc_blocks import REPO, blocks, run_page, untagged_command_blocks

PAGES = ["lab/README.md", *sorted(str(p.relative_to(REPO)) for p in (REPO / "lab" / "docs").glob("*.md"))]

#: (page, first line of the block) -> why it does not run here.
SKIP: dict[tuple[str, str], str] = {
    ("lab/docs/performance.md", "make bench                                  # full table (about 5 minutes)"):
        "minutes of benchmarking; lab/test/bench/test_bench_command.py runs `tactile bench` on a small size",
    ("lab/docs/performance.md", ".venv/bin/tactile bench --sizes 1000 --lengths 2 --latency --json > latency.json"):
        "a latency measurement of minutes; lab/test/bench/test_latency.py measures a short one",
    ("lab/docs/performance.md", "tactile bench --scale-graph --cells 10000 --parts 20 --seconds 30 --json > scale_10000.json"):
        "41 processes for minutes; the page's small run above and lab/test/bench/test_scale_graph.py run the same "
        "command on a small skin",
    ("lab/docs/performance.md", "tactile bench --scale-graph --cells 20 --parts 2 --hosts 2 --seconds 8"):
        "lab/test/bench/test_multi_host.py runs these two-host graphs (the same commands, shorter) and the link drop",
    ("lab/docs/performance.md",
     "tactile bench --scale-graph --cells 10000 --parts 20 --hosts 2 --seconds 30 --json > hosts_10000.json"):
        "43 processes on three hosts for minutes; lab/test/bench/test_multi_host.py runs a small two-host graph",
    ("lab/docs/performance.md", "tactile bench --executor-overhead --rounds 3 --seconds 15 --json"):
        "six 15 s runs of two processes each; lab/test/bench/test_executor_overhead.py runs a short one",
    ("lab/docs/performance.md",
     "tactile bench --executor-overhead --serialized --executor-layouts parts,robot --rounds 2 --seconds 15 --json"):
        "sixteen 15 s runs of two processes each; lab/test/bench/test_executor_overhead.py runs a short one",
    ("lab/docs/performance.md", "tactile bench --read-cost --read-cost-cells 200 --rounds 3 --json"):
        "seven passes over 4 s of 200 cells' frames, about a minute; lab/test/bench/test_read_cost.py runs the same "
        "command with 20 cells and one round",
    ("lab/docs/performance.md", "tactile bench --model-save"):
        "a benchmark of 100 durable saves of a 1,000-class model; lab/test/bench/test_model_save_bench.py runs a "
        "small one",
}
#: page -> the test that runs that page's command blocks with the files they need
RUN_ELSEWHERE = {"lab/docs/import.md": "lab/test/datasets/test_import_docs.py"}


def test_command_blocks_are_tagged():
    untagged = untagged_command_blocks(PAGES)
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
    run_page(page, SKIP, tmp_path)
