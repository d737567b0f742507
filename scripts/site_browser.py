"""The built documentation site in a real headless browser: Debian's chromium
(``/usr/bin/chromium``, installed by ``scripts/install-chromium.sh``) driven by Playwright.

    python scripts/site_browser.py SITE_DIR                 # check every page; exit 1 on a fault
    python scripts/site_browser.py SITE_DIR --pictures DIR  # and take the home and results pages'
                                                            # screenshots (site_home.png, ...)

The site is served on 127.0.0.1 from a free port for the check (its search reads its index
with a request, which a ``file://`` page may not make). The browser starts with a fresh profile
and without any background networking: the machine may have no network.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
VIEWPORT = {"width": 1280, "height": 900}
PICTURES = {"site_home.png": "",
            "site_results.png": "results/camera/"
                                "#the-sampled-policy-the-one-the-constraints-are-learned-for"}
"""Screenshot file -> page (its path under the site)."""


@dataclass
class PageReport:
    """What one page showed: its title, console errors, images that did not load."""

    path: str
    title: str = ""
    errors: list[str] = field(default_factory=list)
    broken_images: list[str] = field(default_factory=list)
    images: int = 0


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:
        pass


@contextmanager
def serve(site: Path) -> Iterator[str]:
    """Serves ``site`` on 127.0.0.1 from a free port; yields its base URL."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


@contextmanager
def browser() -> Iterator:
    """A Playwright browser context on Debian's chromium, with a fresh profile."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="crllk-chromium-") as profile, \
            sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            profile, executable_path=str(CHROMIUM), headless=True, args=FLAGS,
            viewport=VIEWPORT, service_workers="block")
        try:
            yield context
        finally:
            context.close()


def pages(site: Path) -> list[str]:
    """Every page of the built site, as paths under its root (``""`` is the home page)."""
    found = []
    for index in sorted(site.rglob("index.html")):
        relative = index.parent.relative_to(site).as_posix()
        found.append("" if relative == "." else relative + "/")
    return found


def check_page(context, base: str, path: str) -> PageReport:
    """Loads one page: its console errors, uncaught exceptions, failed requests, and every
    image that did not load."""
    report = PageReport(path)
    page = context.new_page()
    page.on("console", lambda m: report.errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: report.errors.append(f"uncaught: {e}"))
    page.on("requestfailed", lambda r: report.errors.append(f"failed: {r.url}")
            if r.url.startswith(base) else None)
    page.on("response", lambda r: report.errors.append(f"{r.status}: {r.url}")
            if r.status >= 400 else None)
    page.goto(base + path, wait_until="load")
    report.title = page.title()
    images = page.eval_on_selector_all(
        "article img", "els => els.map(e => [e.currentSrc || e.src, e.complete, e.naturalWidth])")
    report.images = len(images)
    report.broken_images = [src for src, complete, width in images if not complete or width == 0]
    page.close()
    return report


def check_navigation(context, base: str) -> str:
    """From the home page, follows the navigation's link to Training; returns the new title."""
    page = context.new_page()
    page.goto(base, wait_until="load")
    page.locator("nav.md-nav--primary a.md-nav__link", has_text="Training").first.click()
    page.wait_for_url("**/training/")
    title = page.title()
    page.close()
    return title


def search(context, base: str, query: str) -> list[str]:
    """Types ``query`` into the site's search; returns the titles of the results."""
    page = context.new_page()
    page.goto(base, wait_until="load")
    page.locator("label.md-search__icon, .md-search__input").first.click()
    # the search index loads in a worker; a query typed before it is ready finds nothing
    page.wait_for_function("""() => {
        const meta = document.querySelector('.md-search-result__meta');
        return meta && meta.textContent.trim() && !/initializ/i.test(meta.textContent);
    }""", timeout=60_000)
    # typed key by key: the search answers keyboard events, not a value set at once
    page.locator("input.md-search__input").press_sequentially(query, delay=50)
    page.wait_for_selector(".md-search-result__item", timeout=30_000)
    titles = page.locator(".md-search-result__item h1, .md-search-result__item h2") \
        .all_inner_texts()
    page.close()
    return titles


def screenshot(context, base: str, path: str, out: Path) -> None:
    page = context.new_page()
    page.goto(base + path, wait_until="load")
    page.wait_for_function("Array.from(document.images).every(i => i.complete)")
    page.wait_for_timeout(1000)  # the header's title fades in after a jump to an anchor
    out.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(out))
    page.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("site", type=Path)
    parser.add_argument("--pictures", type=Path, help="write the screenshots here")
    args = parser.parse_args(argv)
    faults = 0
    with serve(args.site) as base, browser() as context:
        for path in pages(args.site):
            report = check_page(context, base, path)
            for problem in [*report.errors, *(f"image: {i}" for i in report.broken_images)]:
                print(f"/{path}: {problem}")
                faults += 1
        print(f"navigation: {check_navigation(context, base)}")
        print(f"search 'Lagrange': {len(search(context, base, 'Lagrange'))} results")
        if args.pictures:
            for name, path in PICTURES.items():
                screenshot(context, base, path, args.pictures / name)
                print(f"wrote {args.pictures / name}")
    return 1 if faults else 0


if __name__ == "__main__":
    sys.exit(main())
