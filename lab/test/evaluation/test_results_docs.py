"""lab/docs/results.md and README's "What to expect" are renderings of lab/docs/results.json, never hand-typed."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from tactile_descriptors_lab.evaluation.report import (
    FEATURE_DEFINITION,
    FIGURES,
    README_BEGIN,
    README_END,
    render_markdown,
    section_provenance,
    update_readme,
    what_to_expect,
)
from tactile_descriptors_ros.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]


def _results() -> dict:
    return json.loads((ROOT / "lab" / "docs" / "results.json").read_text())


def test_readme_what_to_expect_is_generated_from_results_json():
    readme = (ROOT / "README.md").read_text()
    assert readme.count(README_BEGIN) == 1 and readme.count(README_END) == 1
    block = readme[readme.index(README_BEGIN):readme.index(README_END) + len(README_END)]
    assert block == what_to_expect(_results()), "README is stale: run `make report-length` (or `make report`)"


def test_results_md_is_the_rendering_of_results_json():
    figs = {k: f"figures/{f}" for k, f in FIGURES.items() if (ROOT / "lab" / "docs" / "figures" / f).is_file()}
    got = (ROOT / "lab" / "docs" / "results.md").read_text().splitlines()
    want = render_markdown(_results(), figs).splitlines()
    # the header names the machine the run was made on; everything else must match line for line
    assert [g for g in got if "Runtime of the full run" not in g] == \
        [w for w in want if "Runtime of the full run" not in w]


def test_what_to_expect_quotes_the_figures_it_is_given(tmp_path):
    res = _results()
    changed = copy.deepcopy(res)
    changed["length"]["combined | 1-6"]["classifiers"]["svm"]["accuracy"] = 0.5123
    changed["short"]["combined | 1"]["classifiers"]["svm"]["accuracy"] = 0.4321
    text = what_to_expect(changed)
    assert "51.2 %" in text and "43.2 %" in text and text != what_to_expect(res)
    del changed["short"]["combined | 1"]
    with pytest.raises(ConfigError, match="short"):
        what_to_expect(changed)
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{README_BEGIN}\nold figures\n{README_END}\nrest\n")
    update_readme(readme, res)
    assert readme.read_text() == f"intro\n{what_to_expect(res)}\nrest\n"
    readme.write_text("no block here\n")
    with pytest.raises(ConfigError, match="block"):
        update_readme(readme, res)


def _section(md: str, heading: str) -> str:
    text = md.split(heading, 1)[1]
    return text.split("\n## ", 1)[0]


def test_a_section_measured_with_another_feature_definition_says_so_with_its_date():
    res = copy.deepcopy(_results())
    res["provenance"]["headline"] = {"date": "2026-01-02", "features": "bands from an older filter"}
    res["provenance"]["sweep"] = section_provenance("2026-03-04")
    res["provenance"].pop("ablation")
    md = render_markdown(res, {})
    head = _section(md, "## Headline")
    assert "**Not regenerated with this release's features**: measured 2026-01-02 with bands from an older filter" \
        in head and "--only headline" in head
    sweep = _section(md, "## Accuracy against window length")
    assert f"*Measured 2026-03-04 with {FEATURE_DEFINITION}.*" in sweep and "Not regenerated" not in sweep
    assert "is not recorded" in _section(md, "## Ablations")


def test_what_to_expect_dates_figures_of_an_earlier_feature_definition():
    res = copy.deepcopy(_results())
    for sec in ("length", "length_cv", "short"):
        res["provenance"][sec] = section_provenance("2026-03-04")
    current = what_to_expect(res)
    assert "earlier feature definition" not in current
    res["provenance"]["short"] = {"date": "2026-01-02", "features": "bands from an older filter"}
    lines = what_to_expect(res).splitlines()
    touch = next(line for line in lines if line.startswith("- **Touch length**"))
    assert touch.endswith("(measured 2026-01-02 with an earlier feature definition than this release's: see "
                          "`lab/docs/results.md`).")
    head = next(line for line in lines if line.startswith("- **Accuracy on real BioTac data**"))
    assert "earlier feature definition" not in head
