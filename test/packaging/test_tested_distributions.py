"""The README claims as tested exactly the ROS 2 distributions CI runs the tests on."""

from __future__ import annotations

import re


def _ci_distributions(repo_dir) -> set[str]:
    """The ROS_DISTRO of every ``make test`` line of ``.ci/run`` (the Makefile's default where none is set)."""
    default = re.search(r"^ROS_DISTRO \?= (\w+)$", (repo_dir / "Makefile").read_text(), re.M).group(1)
    runs = [line for line in (repo_dir / ".ci" / "run").read_text().splitlines()
            if re.match(r"\s*make test\b", line)]
    assert runs, "no make test in .ci/run"
    return {(re.search(r"\bROS_DISTRO=(\w+)", line) or [None, default])[1] for line in runs}


def _readme_tested(repo_dir) -> tuple[set[str], set[str]]:
    """The distributions the README's "Tested:" paragraph names as tested, and those it calls untested."""
    text = (repo_dir / "README.md").read_text()
    para = re.search(r"^Tested: (.+?)\n\n", text, re.M | re.S).group(1)
    named = {d.lower() for d in re.findall(r"\*\*(\w+)\*\*", para)}
    untested = {d.lower() for d in re.findall(r"\*\*(\w+) is untested\*\*", para)}
    return named - untested, untested


def test_readme_claims_exactly_the_distributions_ci_tests(repo_dir):
    tested, untested = _readme_tested(repo_dir)
    assert tested == _ci_distributions(repo_dir)
    assert untested == {"humble"}  # named, and said to be untested (no wheels here)
