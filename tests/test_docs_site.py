"""The manual in two layers: a short README.md, and docs/ built by MkDocs into a site that works offline."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_is_the_short_layer_and_points_to_every_page_of_the_manual():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    for heading in ("## Two commands", "## The daily operation", "## Commands", "## Where to look next"):
        assert heading in readme
    index = (ROOT / "docs" / "index.md").read_text()
    linked = set(re.findall(r"\]\(docs/([\w.-]+\.md)", readme)) | set(re.findall(r"\]\(([\w.-]+\.md)", index))
    for page in ("settings.md", "operations.md", "models.md", "routing.md", "planning.md", "tables.md",
                 "benchmarks.md"):
        assert (ROOT / "docs" / page).is_file() and page in linked, page


@pytest.mark.slow  # a child process builds the whole manual
def test_mkdocs_builds_the_manual_strictly_into_pages_that_load_nothing_from_elsewhere(tmp_path):
    site = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
                        "--site-dir", str(site)], cwd=ROOT, capture_output=True, text=True, timeout=120,
                       check=False)
    assert r.returncode == 0, r.stderr[-3000:]
    pages = sorted(p.stem for p in (ROOT / "docs").glob("*.md"))
    for stem in pages:
        html = (site / f"{stem}.html").read_text()
        # every script, style and image comes from the site itself (ships and operations centres run air-gapped)
        external = re.findall(r"<(?:script|link|img)[^>]+(?:src|href)=\"(https?:)?//[^\"]+", html)
        assert not external, (stem, external)
    assert "Tables for analysts" in (site / "tables.html").read_text()
    # no nav in mkdocs.yml: a page added under docs/ is listed by every page of the site
    home = (site / "index.html").read_text()
    for stem in pages:
        assert f'href="{stem}.html"' in home or stem == "index", stem
