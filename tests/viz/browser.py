"""A real headless Chromium driven through chromedriver (selenium), for the viewer tests.

Chromium and chromedriver come from Debian's packages (``.ci/run`` installs them); on a
machine without them the tests that use :func:`chromium` skip with the reason.
"""

from __future__ import annotations

import io
import os
import shutil
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = Path(os.environ.get("MOCAPKIT_TEST_ARTIFACTS", REPO / "test-artifacts"))

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1280,800",
)


def _find(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    path = Path("/usr/bin") / name
    return str(path) if path.exists() else None


def start_chromium(profile_dir: Path) -> Any:
    """A selenium driver of a fresh headless Chromium (skips the test when unavailable)."""
    browser, driver = _find("chromium"), _find("chromedriver")
    if browser is None or driver is None:
        pytest.skip(
            "headless Chromium is not installed (Debian: apt-get install chromium "
            "chromium-driver; .ci/run installs them)"
        )
    webdriver = pytest.importorskip(
        "selenium.webdriver", reason="selenium is not installed (pip install -e '.[dev]')"
    )
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    os.environ.setdefault("SE_OFFLINE", "true")  # never let selenium fetch a driver
    opts = Options()
    opts.binary_location = browser
    for flag in CHROMIUM_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={profile_dir}")
    return webdriver.Chrome(service=Service(executable_path=driver), options=opts)


@pytest.fixture
def chromium(tmp_path: Path) -> Iterator[Any]:
    drv = start_chromium(tmp_path / "chromium-profile")
    try:
        yield drv
    finally:
        drv.quit()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def png_rgb(png: bytes) -> np.ndarray:
    """A PNG as an (H, W, 3) uint8 array (matplotlib's reader: no extra dependency)."""
    import matplotlib.image

    img = matplotlib.image.imread(io.BytesIO(png), format="png")
    return np.round(np.asarray(img)[..., :3] * 255).astype(np.uint8)


def color_pixels(rgb: np.ndarray, color: tuple[int, int, int], tol: int = 45) -> int:
    """How many pixels lie within ``tol`` of ``color`` in every channel."""
    d = np.abs(rgb.astype(int) - np.array(color)[None, None, :])
    return int(np.all(d <= tol, axis=2).sum())


def save_artifact(name: str, data: bytes) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / name
    path.write_bytes(data)
    return path
