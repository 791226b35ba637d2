"""mkdocs hooks (`hooks:` in mkdocs.yml): fill the generated parts of the pages at build time.

A page holds a marker where a generated part goes: `<!-- generated: config-reference -->` (the pydantic models) or
`<!-- generated: benchmarks -->` (benchmarks/results/). A marker that names nothing known fails the build.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # mkdocs loads this file by path: make the repository's packages importable
    sys.path.insert(0, str(ROOT))

from docsite import benchmarks_page, config_reference  # noqa: E402

MARKER = re.compile(r"<!-- generated: ([a-z-]+) -->")

GENERATORS = {
    "config-reference": config_reference.markdown,
    "benchmarks": lambda: benchmarks_page.markdown(ROOT / "benchmarks" / "results"),
}


def expand(markdown: str) -> str:
    """The page with every marker replaced by what it names."""
    def one(match: re.Match) -> str:
        name = match.group(1)
        if name not in GENERATORS:
            raise ValueError(f"unknown generated part {name!r}; known: {', '.join(GENERATORS)}")
        return GENERATORS[name]()

    return MARKER.sub(one, markdown)


def on_files(files, config):
    """mkdocs: the figures in benchmarks/results/ join the site under results/, for the benchmarks page."""
    from mkdocs.structure.files import File

    results = ROOT / "benchmarks" / "results"
    for png in sorted(results.rglob("*.png")):
        files.append(File(f"results/{png.relative_to(results).as_posix()}", str(results.parent), config["site_dir"],
                          config["use_directory_urls"]))
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    """mkdocs: a page's markdown before it is rendered."""
    return expand(markdown)
