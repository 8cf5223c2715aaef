"""The documentation: the site builds strictly (no broken link, anchor, snippet or API reference; mkdocs.yml's
``validation``), its command-line reference is generated, and the README is a short entry point whose links work."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _html_of(page: str, site: Path) -> Path:
    """The built HTML of ``docs/<page>.md`` (MkDocs' directory URLs: ``guide/gait.md`` → ``guide/gait/index.html``)."""
    stem = page.removesuffix(".md")
    return site / ("index.html" if stem == "index" else stem.removesuffix("/index") + "/index.html")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    out = tmp_path_factory.mktemp("docs") / "site"
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent))
    command = [mkdocs] if mkdocs else [sys.executable, "-m", "mkdocs"]
    result = subprocess.run(
        [*command, "build", "--strict", "--site-dir", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, "mkdocs build --strict failed:\n" + result.stderr[-5000:]
    return out


def test_site_builds_strictly(site):
    assert _html_of("index.md", site).is_file()
    for page in ("getting-started.md", "extending.md", "guide/refinement.md", "api/refinement.md"):
        assert _html_of(page, site).is_file(), page


def test_cli_reference_is_generated_from_the_parser(site):
    from mocapkit.cli import build_parser

    html = _html_of("cli.md", site).read_text()
    assert "cli-reference" not in html  # the marker was replaced
    commands = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction").choices
    for name in commands:
        assert f"mocapkit {name}</code>" in html, name


def test_each_guide_lists_every_registered_method(site):
    """The guides' method tables come from the registry: every configs/<task>/method/NAME.yaml is on its guide."""
    from mocapkit.train.registry import TASKS, method_names

    for task in TASKS:
        html = _html_of(f"guide/{task}.md", site).read_text()
        assert "<!-- methods:" not in html, task  # the marker was replaced
        for name in method_names(task):
            assert f"<code>{name}</code>" in html, (task, name)


def test_readme_is_short():
    lines = README.read_text().splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines; the details belong in docs/"


def test_readme_links_resolve(site):
    """Every relative link of the README names a file of the repository, and an anchor into docs/ exists there."""
    for target in re.findall(r"\]\(([^)\s]+)\)", README.read_text()):
        if re.match(r"[a-z]+://", target):
            continue
        path, _, anchor = target.partition("#")
        assert (ROOT / path).exists(), f"README.md links to {path}, which does not exist"
        if anchor and path.startswith("docs/") and path.endswith(".md"):
            html = _html_of(path.removeprefix("docs/"), site).read_text()
            assert f'id="{anchor}"' in html, f"README.md links to {target}: no such anchor"
