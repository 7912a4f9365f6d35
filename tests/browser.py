"""Looking at a report page in a real browser: headless Chromium screenshots, and finding a
picture of the page in them."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

__all__ = ["CHROMIUM", "find_picture", "needs_chromium", "screenshot"]

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (the README's apt line installs it; CI has it)")


def screenshot(page: Path, workdir: Path, size: tuple[int, int] = (1280, 6000)) -> np.ndarray:
    """The grey screenshot (height x width) of ``page`` in a ``size`` (width, height) window
    at device scale 1, taken offline with a fresh profile under ``workdir``."""
    assert CHROMIUM is not None
    shot = workdir / "screenshot.png"
    argv = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--hide-scrollbars",
        f"--user-data-dir={workdir / 'profile'}",
        "--force-device-scale-factor=1",
        f"--window-size={size[0]},{size[1]}",
        f"--screenshot={shot}",
        page.as_uri(),
    ]
    done = subprocess.run(
        argv, check=False, capture_output=True, text=True, timeout=120, env={"HOME": str(workdir), "PATH": "/usr/bin:/bin"}
    )
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    image = cv2.imread(str(shot), cv2.IMREAD_GRAYSCALE)
    assert image.shape == (size[1], size[0])
    return image


def find_picture(screen: np.ndarray, picture: Path) -> tuple[float, int]:
    """Best normalised-correlation score of ``picture``, drawn at its natural size, anywhere in
    ``screen``, and the top row where it is."""
    template = cv2.imread(str(picture), cv2.IMREAD_GRAYSCALE)
    _, best, _, (_, y) = cv2.minMaxLoc(cv2.matchTemplate(screen, template, cv2.TM_CCOEFF_NORMED))
    return float(best), int(y)
