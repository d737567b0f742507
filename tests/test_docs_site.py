"""The documentation site: it builds strictly (``make docs``), the README stays a short front
page whose sections moved to the site, and the built site works in a real headless browser
(Debian's chromium driven by Playwright): every page loads without a console error and shows
its images, the navigation and the search work."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from docs_pages import DOCS, REPO, page

MOVED = {
    "Set-up: two commands": ("getting-started.md", "## Set-up: two commands"),
    "Training": ("training.md", "# Training"),
    "Evaluation and experiments": ("evaluation.md", "# Evaluation and experiments"),
    "Results": ("results/index.md", "# Results"),
    "Recordings (rerun)": ("recordings.md", "# Recordings and the viewer"),
    "Live view of a training run": ("recordings.md", "## Live view of a training run"),
    "Everyday use": ("getting-started.md", "## Everyday use"),
    "Scaling out": ("scaling-out.md", "# Scaling out"),
    "Deployment on a Duckiebot": ("sim-to-real.md", "# Sim-to-real"),
    "Tasks and maps": ("simulation.md", "## Tasks and maps"),
    "The simulation": ("simulation.md", "## The simulation"),
    "Benchmarks": ("benchmarks.md", "# Benchmarks"),
    "Security": ("security.md", "# Security"),
    "Tests": ("development.md", "## Tests"),
    "Layout": ("development.md", "## Layout"),
}
"""Each section the README had before the site, and the page and heading it moved to."""


def build(config: Path, site: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config),
                           "-d", str(site)], cwd=config.parent, capture_output=True, text=True,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, timeout=300)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site as ``make docs`` builds it (strict), into a temporary folder."""
    out = tmp_path_factory.mktemp("site")
    done = build(REPO / "mkdocs.yml", out)
    assert done.returncode == 0, done.stderr[-5000:]
    return out


def test_the_readme_is_a_short_front_page():
    readme = page("README.md")
    assert len(readme.splitlines()) <= 250
    for heading in ("## Set-up: two commands", "## The headline result",
                    "## The five most used commands", "## Documentation", "## How to cite",
                    "## Licence"):
        assert heading in readme.splitlines()
    assert "make train" in readme and "make test" in readme


@pytest.mark.parametrize("section", MOVED)
def test_every_section_the_readme_had_is_on_the_site(section):
    name, heading = MOVED[section]
    assert heading in page(name).splitlines()
    link = f"(docs/{name})"
    assert link in page("README.md") or name.startswith(("recordings", "simulation"))


def test_every_page_is_in_the_navigation(site):
    for name in (p.relative_to(DOCS) for p in DOCS.rglob("*.md")):
        built = site / name.with_suffix("") / "index.html"
        if name.name == "index.md":
            built = site / name.parent / "index.html"
        assert built.is_file(), name


def test_the_api_reference_has_every_package_and_module(site):
    """Every package of crllk has its page, listing each of its modules; every module at the
    top of the package is on a page too (the commands on the pages that describe them)."""
    from docs_pages import _hook

    packages = {p.parent.name for p in (REPO / "crllk").glob("*/__init__.py")} - {"conf"}
    assert packages == set(_hook().REFERENCE)
    for package in packages:
        built = (site / "reference" / package / "index.html").read_text()
        for module in (REPO / "crllk" / package).glob("[!_]*.py"):
            assert f'id="crllk.{package}.{module.stem}"' in built, module
    commands = {"train", "evaluate", "record", "experiments", "pictures", "screenshots", "demo",
                "export", "deploy", "convert"}
    pages = "".join(p.read_text() for p in (site / "reference").rglob("index.html"))
    for module in (REPO / "crllk").glob("[!_]*.py"):
        if module.stem not in commands:
            assert f'id="crllk.{module.stem}"' in pages, module


def test_the_results_pages_show_the_committed_tables(site):
    camera = (site / "results" / "camera" / "index.html").read_text()
    for table in ("Table 1: small_loop", "CRLLK vs PPO: zigzag", "CRLLK vs PPO: obstacle_loop",
                  "By start direction: obstacle_loop"):
        assert table in camera
    for picture in REPO.glob("results/*/*.png"):
        assert (site / picture.relative_to(REPO)).read_bytes() == picture.read_bytes()


def test_a_broken_link_fails_the_build(tmp_path):
    """Strict mode: what ``make docs`` would publish with a dead link is refused."""
    copy = tmp_path / "repo"
    shutil.copytree(DOCS, copy / "docs")
    shutil.copy(REPO / "mkdocs.yml", copy / "mkdocs.yml")
    shutil.copy(REPO / "README.md", copy / "README.md")
    shutil.copytree(REPO / "results", copy / "results",
                    ignore=shutil.ignore_patterns("runs"))
    (copy / "crllk").symlink_to(REPO / "crllk")
    index = copy / "docs" / "index.md"
    index.write_text(index.read_text() + "\n[gone](no-such-page.md)\n")
    done = build(copy / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0
    assert "no-such-page.md" in done.stderr


def _browser_module():
    spec = importlib.util.spec_from_file_location("site_browser",
                                                  REPO / "scripts" / "site_browser.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def browser_site(site):
    """The built site served on 127.0.0.1, and a chromium to look at it."""
    module = _browser_module()
    if not module.CHROMIUM.exists():
        if os.environ.get("CRLLK_REQUIRE_CHROMIUM"):
            pytest.fail(f"{module.CHROMIUM} is missing (scripts/install-chromium.sh installs it)")
        pytest.skip(f"{module.CHROMIUM} is missing: run scripts/install-chromium.sh as root")
    with module.serve(site) as base, module.browser() as context:
        yield module, base, context


def test_every_page_loads_in_the_browser_without_errors(browser_site, site):
    module, base, context = browser_site
    paths = module.pages(site)
    assert len(paths) >= 30
    shown = 0
    for path in paths:
        report = module.check_page(context, base, path)
        assert report.errors == [], (path, report.errors)
        assert report.broken_images == [], (path, report.broken_images)
        assert report.title.endswith("crllk"), (path, report.title)
        shown += report.images
    assert shown >= 10


def test_the_navigation_and_the_search_work(browser_site):
    module, base, context = browser_site
    assert module.check_navigation(context, base).startswith("Training")
    titles = module.search(context, base, "Lagrange")
    assert titles and any("Lagrang" in t or "lagrang" in t for t in titles)


def test_the_screenshots_show_the_site(browser_site, tmp_path):
    """What ``make docs-pictures`` commits: PNGs of the home and results pages, not blank."""
    from PIL import Image

    module, base, context = browser_site
    for name, path in module.PICTURES.items():
        module.screenshot(context, base, path, tmp_path / name)
        image = Image.open(tmp_path / name).convert("L")
        assert image.size == (module.VIEWPORT["width"], module.VIEWPORT["height"])
        low, high = image.getextrema()
        assert high - low > 100
        assert (DOCS / "images" / name).read_bytes()[:4] == b"\x89PNG"


def test_every_command_the_documentation_names_exists():
    """Each ``python -m crllk.<module>`` of the README and of every page is a module that runs
    (a command renamed or moved fails here, not in a reader's shell)."""
    from docs_pages import pages

    named = set()
    for name in ["README.md", *pages()]:
        named |= set(re.findall(r"python -m (crllk(?:\.\w+)+)", page(name)))
    assert {"crllk.train", "crllk.evaluate", "crllk.export"} <= named
    for module in named:
        path = REPO / Path(*module.split("."))
        assert path.with_suffix(".py").is_file() or (path / "__main__.py").is_file(), module
