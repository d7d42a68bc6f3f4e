"""Browser tests of the operator page: the real app on the simulated rig, served by uvicorn on a
free loopback port (in a thread), driven in a real headless Chromium (Debian's ``chromium``
and ``chromium-driver``, through Selenium; nothing is downloaded).

Every test collects the browser's console and fails on an error it did not expect; screenshots
go to ``test-artifacts/web/<width>x<height>/`` (git-ignored), and the ones the documentation
shows to ``docs/images/operator-*.png`` when missing or with ``TOFTWIN_DOC_SCREENSHOTS=1``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn

from service.api.app import create_app
from tests.service.api.conftest import AUTH, TOKEN, make_settings

REPO = Path(__file__).parents[2]
ARTIFACTS = REPO / "test-artifacts" / "web"
DOC_IMAGES = REPO / "docs" / "images"
#: the screen the documentation's screenshots are taken at
DOC_SIZE = (1280, 800)
SIZES = [(1280, 800), (1920, 1080)]
APT = "apt-get install chromium chromium-driver"


def chromium_paths(path: str | None = None) -> tuple[str, str]:
    """Chromium and its driver on ``path`` (default: ``PATH`` and ``/usr/bin``), or the test
    fails saying what is missing and how to install it (never a skip: a machine without the
    browser must not pass the browser tests silently)."""
    path = path if path is not None else os.pathsep.join((os.environ.get("PATH", ""), "/usr/bin"))
    browser = shutil.which("chromium", path=path) or shutil.which("chromium-browser", path=path)
    driver = shutil.which("chromedriver", path=path)
    missing = [n for n, p in (("chromium", browser), ("chromedriver (chromium-driver)", driver))
               if p is None]
    if missing:
        pytest.fail(f"the browser tests need a headless Chromium: {' and '.join(missing)} not "
                    f"found on {path!r}; install them with `{APT}` (Debian/Ubuntu)",
                    pytrace=False)
    return browser, driver  # type: ignore[return-value]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """The app on the simulated rig (tiny renders), served by uvicorn in a thread."""

    def __init__(self, data_dir: Path, **overrides: Any) -> None:
        self.app = create_app(make_settings(data_dir, **overrides))
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.port, log_level="warning")
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._server.run, daemon=True)

    def __enter__(self) -> Server:
        self._thread.start()
        deadline = time.monotonic() + 60.0
        while not self._server.started:
            assert self._thread.is_alive(), "the server thread ended before it started"
            assert time.monotonic() < deadline, "the server did not start in 60 s"
            time.sleep(0.05)
        self.api = httpx.Client(base_url=self.url, timeout=30.0)
        return self

    def __exit__(self, *exc: object) -> None:
        self.api.close()
        self._server.should_exit = True
        self._thread.join(timeout=30.0)

    def post(self, path: str, body: Any = None) -> httpx.Response:
        return self.api.post(path, headers=AUTH, json=body)

    @property
    def rig(self):
        return self.app.state.lab.lease.rig


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    """One service for the tests of a module (a fresh data directory), instant motions, one
    pose in flight at a time (a pause lands at most one pose after it was asked for), a
    campaign's events checked for every 0.1 s instead of 0.5 s (the page follows a campaign
    sooner; the pause test's margin is the time the next pose takes)."""
    with Server(tmp_path_factory.mktemp("web-data"), pipeline_depth=1,
                sse_interval_s=0.1) as srv:
        yield srv


@pytest.fixture(scope="module")
def moving_server(tmp_path_factory) -> Iterator[Server]:
    """A service whose simulated turntable moves at its real speed (20 deg/s), so that a move
    takes seconds and can be stopped."""
    with Server(tmp_path_factory.mktemp("web-moving"), sim_motion="real") as srv:
        yield srv


#: Chromium's switches for a machine without a network: no host name resolves (but the
#: server's loopback address) and every connection that is not to loopback goes to a proxy
#: that is not there (the discard port), so that an IP address does not get through either
OFFLINE = ("--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
           "--proxy-server=127.0.0.1:9", "--proxy-bypass-list=127.0.0.1")


class Page:
    """A headless Chromium showing the operator page at one window size.

    ``offline``: with the network off (:data:`OFFLINE`), every request the browser makes
    recorded (:meth:`requested_urls`).
    """

    def __init__(self, server: Server, size: tuple[int, int], offline: bool = False) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        browser, driver = chromium_paths()
        os.environ["SE_OFFLINE"] = "true"  # Selenium Manager must never download anything
        options = webdriver.ChromeOptions()
        options.binary_location = browser
        for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                    "--disable-gpu", "--hide-scrollbars", f"--window-size={size[0]},{size[1]}",
                    *(OFFLINE if offline else ())):
            options.add_argument(arg)
        logs = {"browser": "ALL", **({"performance": "ALL"} if offline else {})}
        options.set_capability("goog:loggingPrefs", logs)
        self.driver = webdriver.Chrome(service=Service(executable_path=driver), options=options)
        self.driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
            "width": size[0], "height": size[1], "deviceScaleFactor": 1, "mobile": False})
        self.server = server
        self.size = size
        self.console: list[dict] = []

    def close(self) -> None:
        self.driver.quit()

    # -- navigation and waiting ------------------------------------------------------------------
    def load(self, screen: str = "rig") -> None:
        """A fresh load of the page (never a same-document jump to another screen)."""
        self.driver.get("about:blank")
        self.driver.get(f"{self.server.url}/#{screen}")
        self.wait(lambda: self.js("return document.readyState") == "complete")
        self.wait(lambda: self.find("#devices .device") is not None, "the rig panel")

    def js(self, script: str, *args: Any) -> Any:
        return self.driver.execute_script(script, *args)

    def find(self, css: str):
        from selenium.webdriver.common.by import By

        found = self.driver.find_elements(By.CSS_SELECTOR, css)
        return found[0] if found else None

    def find_all(self, css: str) -> list:
        from selenium.webdriver.common.by import By

        return self.driver.find_elements(By.CSS_SELECTOR, css)

    def text(self, css: str) -> str:
        el = self.find(css)
        return "" if el is None else el.text

    def wait(self, until: Callable[[], Any], what: str = "the condition",
             timeout_s: float = 60.0) -> Any:
        deadline = time.monotonic() + timeout_s
        while True:
            with contextlib.suppress(Exception):
                got = until()
                if got:
                    return got
            if time.monotonic() > deadline:
                self.shot("timeout")
                raise AssertionError(f"{what} did not happen in {timeout_s} s "
                                     f"(page: {self.text('body')[:2000]})")
            time.sleep(0.05)

    # -- acting --------------------------------------------------------------------------------
    def click(self, css: str) -> None:
        """Click the element ``css`` names once it is there, enabled and shown; found afresh on
        every try (a fragment the page fills again replaces its elements), and clicked again
        if it was replaced between finding and clicking."""
        def clicked() -> bool:
            el = self.find(css)
            if not (el.is_enabled() and el.is_displayed()):
                return False
            el.click()  # a StaleElementReferenceException here is one more try
            return True

        self.wait(clicked, f"{css} to be clicked")

    def fill(self, css: str, value: str) -> None:
        el = self.wait(lambda: self.find(css), f"{css} to exist")
        el.clear()
        el.send_keys(value)

    def enter_token(self, token: str = TOKEN) -> None:
        self.fill("#token", token)
        self.click("#token-save")
        self.wait(lambda: "kept" in self.text("#token-state"), "the token to be kept")

    # -- evidence ------------------------------------------------------------------------------
    def shot(self, name: str, doc: bool = False) -> Path:
        """A screenshot of the window: a test artefact, and (``doc``, at the documentation's
        size) the documentation's ``docs/images/operator-<name>.png`` - written when it is
        missing or when ``TOFTWIN_DOC_SCREENSHOTS=1`` asks for fresh ones, so that an ordinary
        test run leaves the committed images alone (every run differs in times and ids)."""
        folder = ARTIFACTS / f"{self.size[0]}x{self.size[1]}"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{name}.png"
        self.driver.save_screenshot(str(path))
        doc_path = DOC_IMAGES / f"operator-{name}.png"
        if doc and self.size == DOC_SIZE and (
                not doc_path.exists() or os.environ.get("TOFTWIN_DOC_SCREENSHOTS") == "1"):
            shutil.copyfile(path, doc_path)
        return path

    def requested_urls(self) -> list[str]:
        """Every URL the browser asked for since the last call (``offline`` pages only): the
        network log's requests, those that failed or were blocked included."""
        urls = []
        for entry in self.driver.get_log("performance"):
            message = json.loads(entry["message"])["message"]
            if message["method"] == "Network.requestWillBeSent":
                urls.append(message["params"]["request"]["url"])
        return urls

    def take_console(self) -> list[dict]:
        """The console entries since the last call."""
        entries = self.driver.get_log("browser")
        self.console += entries
        return entries

    def assert_no_console_errors(self, allowed: tuple[str, ...] = ()) -> None:
        """No error in the console, but for messages containing one of ``allowed`` (a request
        that the test made fail on purpose, e.g. ``"422"``)."""
        errors = [e for e in self.take_console() if e["level"] == "SEVERE"
                  and not any(a in e["message"] for a in allowed)]
        assert not errors, f"errors in the browser's console: {errors}"


@pytest.fixture(scope="module")
def page_at() -> Iterator[Callable[[Server, tuple[int, int]], Page]]:
    """Factory of browser windows (one per server and size, reused within the module)."""
    pages: dict[tuple[int, tuple[int, int]], Page] = {}

    def get(server: Server, size: tuple[int, int]) -> Page:
        key = (id(server), size)
        if key not in pages:
            pages[key] = Page(server, size)
        return pages[key]

    yield get
    for p in pages.values():
        p.close()


@pytest.fixture
def page(server, page_at) -> Iterator[Page]:
    """The page at 1280x800; the test fails on any console error it leaves."""
    p = page_at(server, DOC_SIZE)
    p.take_console()
    yield p
    p.assert_no_console_errors()
