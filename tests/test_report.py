"""report.html: one self-contained page per run, checked in a real headless browser
(Debian's Chromium; .ci/run installs it, so CI always runs this; where it is missing the test
says so and is skipped)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from symtrack.cli import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--virtual-time-budget=5000"]


def _dom(page: Path, profile: Path) -> str:
    r = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "--dump-dom", page.as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "run"
    assert main(["simulate", "validation", "--out", str(out), "--quiet"]) == 0
    return out / "report.html"


def test_report_is_self_contained(report):
    text = report.read_text()
    imgs = re.findall(r'<img src="([^"]+)"', text)
    assert len(imgs) == 6 and all(src.startswith("data:image/png;base64,") for src in imgs)
    # no link or resource outside the page
    assert not re.search(r'(href|src)="(?!data:|#)', text)
    assert "lateral_deviation_m" in text and "Validation" in text and "[[torque]]" in text


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium; .ci/run does)")
def test_report_loads_in_a_headless_browser_with_every_image(report, tmp_path):
    dom = _dom(report, tmp_path / "profile")
    m = re.search(r'data-images-ok="(\d+)/(\d+)"', dom)
    assert m, "the page's load check did not run"
    ok, total = int(m.group(1)), int(m.group(2))
    assert total == 6 and ok == total
    # a broken image is reported as such by the same check
    broken = tmp_path / "broken.html"
    broken.write_text(report.read_text().replace("data:image/png;base64,", "data:image/png;base64,AAAA", 1))
    m = re.search(r'data-images-ok="(\d+)/(\d+)"', _dom(broken, tmp_path / "profile2"))
    assert m and int(m.group(1)) == total - 1
