"""Debian's chromium driven by Selenium for the browser tests (``rce annotate``, ``rce review``): skipped, with the
reason, where chromium or chromium-driver is missing (``make test`` installs both as root)."""

from __future__ import annotations

import shutil

import pytest


def chromium_driver(width: int, height: int):
    """A headless chromium WebDriver of ``width`` x ``height`` CSS pixels at scale 1 (the caller quits it)."""
    chromium, driver_bin = shutil.which("chromium"), shutil.which("chromedriver")
    if not (chromium and driver_bin):
        pytest.skip("needs Debian's chromium and chromium-driver (`make test` installs them as root)")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
              f"--window-size={width},{height}", "--force-device-scale-factor=1"):
        opts.add_argument(a)
    return webdriver.Chrome(service=Service(executable_path=driver_bin), options=opts)
