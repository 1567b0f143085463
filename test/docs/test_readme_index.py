"""The README's Documentation section lists every page of both packages, one line each."""

from __future__ import annotations

import re


def test_readme_lists_every_page_once(repo_dir):
    readme = (repo_dir / "README.md").read_text()
    section = readme[readme.index("## Documentation\n"):]
    nxt = section.find("\n## ", 5)
    section = section[: nxt if nxt != -1 else None]
    listed = re.findall(r"^- `((?:lab/)?docs/[\w.]+\.md)`: \S", section, re.M)
    pages = sorted(str(p.relative_to(repo_dir)) for d in ("docs", "lab/docs") for p in (repo_dir / d).glob("*.md"))
    assert sorted(listed) == pages, f"missing: {set(pages) - set(listed)}, stale: {set(listed) - set(pages)}"
    assert len(listed) == len(set(listed)), "a page is listed twice"
