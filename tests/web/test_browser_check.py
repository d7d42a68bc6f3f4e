"""Without Chromium the browser tests fail, naming what is missing and how to install it."""

from __future__ import annotations

import pytest

from tests.web.conftest import APT, chromium_paths


def test_a_machine_without_chromium_fails_the_browser_tests_naming_the_package(tmp_path):
    with pytest.raises(pytest.fail.Exception) as failed:
        chromium_paths(path=str(tmp_path))  # a PATH with nothing on it
    message = str(failed.value)
    assert "chromium and chromedriver (chromium-driver) not found" in message
    assert APT in message


def test_the_browser_and_its_driver_are_found_where_debian_puts_them():
    browser, driver = chromium_paths()
    assert browser.endswith(("chromium", "chromium-browser")) and driver.endswith("chromedriver")
