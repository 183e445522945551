"""Open a page in headless Chromium: the DOM after its scripts ran, or a screenshot.

Used by the tests of the HTML report and by ``benchmarks/html_report.py``.  Each run
gets a fresh profile directory and no background networking, so runs do not share
state and the browser fetches nothing the page itself does not ask for.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

#: Executable names tried in order (Debian's package is ``chromium``).
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars")


def find_chromium() -> str | None:
    """Path of a Chromium executable, or None."""
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass
class PageRun:
    """What one headless run gave: the DOM (``--dump-dom``), stderr, wall time (s)."""

    dom: str
    stderr: str
    wall_s: float

    def status(self) -> dict[str, str]:
        """Attributes and text of the report's ``<output id="status">`` element."""
        m = re.search(r'<output id="status"([^>]*)>(.*?)</output>', self.dom, re.DOTALL)
        if not m:
            return {}
        attrs = dict(re.findall(r'([\w-]+)="([^"]*)"', m.group(1)))
        attrs["text"] = m.group(2)
        return attrs

    def element_text(self, element_id: str) -> str:
        m = re.search(rf'id="{element_id}"[^>]*>(.*?)</', self.dom, re.DOTALL)
        return m.group(1) if m else ""


def _run(args: list[str], timeout_s: float) -> tuple[subprocess.CompletedProcess, float]:
    exe = find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium executable found (apt-get install chromium)")
    with tempfile.TemporaryDirectory(prefix="gpsdr-chromium-") as profile:
        t0 = time.perf_counter()
        proc = subprocess.run([exe, *FLAGS, f"--user-data-dir={profile}", *args],
                              capture_output=True, text=True, timeout=timeout_s, check=False)
        return proc, time.perf_counter() - t0


def dump_dom(path: str | Path, fragment: str = "", *, window: str = "1400,1000",
             timeout_s: float = 60.0) -> PageRun:
    """Load ``path`` (plus ``#fragment``) and return the DOM once the page has loaded."""
    url = Path(path).resolve().as_uri() + (f"#{fragment}" if fragment else "")
    proc, wall = _run([f"--window-size={window}", "--enable-logging=stderr", "--v=0",
                       "--dump-dom", url], timeout_s)
    return PageRun(dom=proc.stdout, stderr=proc.stderr, wall_s=wall)


def screenshot(path: str | Path, png: str | Path, fragment: str = "", *,
               window: str = "1400,1000", timeout_s: float = 60.0) -> float:
    """Render ``path`` to the PNG ``png``; return the wall time (s)."""
    url = Path(path).resolve().as_uri() + (f"#{fragment}" if fragment else "")
    proc, wall = _run([f"--window-size={window}", f"--screenshot={Path(png).resolve()}", url],
                      timeout_s)
    if not Path(png).exists():
        raise RuntimeError(f"chromium wrote no screenshot: {proc.stderr.strip()[-500:]}")
    return wall


def console_errors(stderr: str) -> list[str]:
    """JavaScript errors Chromium logged (``--enable-logging=stderr``)."""
    return [ln for ln in stderr.splitlines()
            if "CONSOLE" in ln and ("Uncaught" in ln or "Error" in ln)]
