"""A real headless browser (Chromium from the Debian archive) opening a page from the file system: what the page's
DOM holds once it has loaded, for tests that check what a reader would see."""

from __future__ import annotations

import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

CHROMIUM = next((shutil.which(name) for name in ("chromium", "chromium-browser", "google-chrome")
                 if shutil.which(name)), None)


def need_browser() -> str:
    if CHROMIUM is None:
        pytest.skip("Chromium not installed (Debian: apt-get install chromium); the page is not checked in a browser")
    return CHROMIUM


class LoadedPage(HTMLParser):
    """The images (src, data-loaded) and the tables (rows of body cells) of a page's DOM after loading."""

    def __init__(self, dom: str):
        super().__init__()
        self.images: dict[str, str | None] = {}
        self.tables: list[int] = []
        self.body: dict[str, str | None] = {}
        self._in_tbody = False
        self.feed(dom)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.images[a.get("src") or ""] = a.get("data-loaded")
        elif tag == "body":
            self.body = a
        elif tag == "tbody":
            self.tables.append(0)
            self._in_tbody = True
        elif tag == "tr" and self._in_tbody:
            self.tables[-1] += 1

    def handle_endtag(self, tag: str) -> None:
        if tag == "tbody":
            self._in_tbody = False


def open_page(path: Path) -> LoadedPage:
    """The page's DOM after its load handlers ran, from headless Chromium."""
    run = subprocess.run([need_browser(), "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom",
                          "--virtual-time-budget=10000", path.resolve().as_uri()],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    return LoadedPage(run.stdout)
