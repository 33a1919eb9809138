"""The workbench in a real browser: JupyterLab driven by Debian's chromium through Playwright.

The test starts JupyterLab on a free localhost port (token auth, no browser, temporary config and a
temporary copy of ``notebooks/`` so that nothing the browser saves lands in git), opens
``01_contour_template.ipynb``, runs all cells from the *Run* menu, waits for the kernel to go idle, moves the
template explorer's threshold slider with the keyboard and asserts that the displayed contour readout
changes. Screenshots land in ``test-output/browser/``.

It is skipped, with a message, only when ``/usr/bin/chromium`` is missing (``make test`` installs it).
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = Path("/usr/bin/chromium")
NOTEBOOK = ROOT / "notebooks" / "01_contour_template.ipynb"
OUTPUT = ROOT / "test-output" / "browser"

CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-dev-shm-usage",
]

# CSS classes the widgets put on themselves (``widget.add_class``) so the browser can find them.
SLIDER_CLASS = "semlab-threshold"
READOUT_CLASS = "semlab-readout"

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(not CHROMIUM.exists(),
                       reason="Debian's chromium (/usr/bin/chromium) is not installed; "
                              "`make test` installs it when run as root"),
]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _write_settings(settings_dir: Path) -> None:
    """User settings for a quiet, deterministic JupyterLab: no news toasts, no windowed notebook."""
    files = {
        # Every cell stays in the DOM, so the test can read every prompt without scrolling.
        "@jupyterlab/notebook-extension/tracker.jupyterlab-settings": {"windowingMode": "none"},
        "@jupyterlab/apputils-extension/notification.jupyterlab-settings":
            {"fetchNews": "false", "checkForUpdates": False},
    }
    for rel, content in files.items():
        path = settings_dir / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(content))


class Lab:
    """A JupyterLab server in a subprocess, serving a temporary directory."""

    def __init__(self, root: Path, workdir: Path):
        self.root = root
        self.port = _free_port()
        self.token = secrets.token_hex(16)
        self.base = f"http://127.0.0.1:{self.port}"
        self.log_path = workdir / "jupyterlab.log"
        env = dict(os.environ)
        env.update(
            SEMLAB_FAST="1",
            JUPYTER_CONFIG_DIR=str(workdir / "config"),
            JUPYTERLAB_SETTINGS_DIR=str(workdir / "settings"),
            JUPYTERLAB_WORKSPACES_DIR=str(workdir / "workspaces"),
            JUPYTER_RUNTIME_DIR=str(workdir / "runtime"),
            PYTHONUNBUFFERED="1",
        )
        env.pop("MPLBACKEND", None)  # the kernel shows figures inline, as for a user
        _write_settings(workdir / "settings")
        cmd = [
            sys.executable, "-m", "jupyterlab",
            "--no-browser", "--allow-root",
            "--ServerApp.ip=127.0.0.1", f"--ServerApp.port={self.port}", "--ServerApp.port_retries=0",
            f"--IdentityProvider.token={self.token}",
            f"--ServerApp.root_dir={root}",
            "--ServerApp.terminals_enabled=False",
            "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
            # window.jupyterapp lets the test read the kernel's real status (as JupyterLab's own
            # Galata tests do); cells are still run through the menu, as a user would.
            "--LabApp.expose_app_in_browser=True",
        ]
        self._log = open(self.log_path, "w")  # noqa: SIM115 - open for the server's lifetime
        self.proc = subprocess.Popen(cmd, env=env, cwd=root, stdout=self._log,
                                     stderr=subprocess.STDOUT, start_new_session=True)

    def wait_ready(self, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        url = f"{self.base}/api/status?token={self.token}"
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"JupyterLab exited with code {self.proc.returncode}:\n{self.log()}")
            try:
                with urllib.request.urlopen(url, timeout=2) as r:
                    if r.status == 200:
                        return
            except (urllib.error.URLError, ConnectionError, TimeoutError, OSError):
                pass
            time.sleep(0.5)
        raise TimeoutError(f"JupyterLab did not answer on {self.base} within {timeout:.0f} s:\n{self.log()}")

    def url(self, notebook: str) -> str:
        return f"{self.base}/lab/tree/{notebook}?token={self.token}"

    def log(self) -> str:
        self._log.flush()
        return self.log_path.read_text(errors="replace")[-4000:]

    def stop(self) -> None:
        if self.proc.poll() is None:
            # The server and its kernels share the session we started it in.
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(timeout=15)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        self._log.close()


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    work = tmp_path_factory.mktemp("jupyterlab")
    root = work / "notebooks"
    shutil.copytree(ROOT / "notebooks", root, ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
    server = Lab(root, work)
    try:
        server.wait_ready()
        yield server
    finally:
        server.stop()


# --- browser helpers --------------------------------------------------------------------------

JS_KERNEL_IDLE = """() => {
  const app = window.jupyterapp;
  const widget = app && app.shell && app.shell.currentWidget;
  const ctx = widget && widget.sessionContext;
  const kernel = ctx && ctx.session && ctx.session.kernel;
  return !!kernel && kernel.status === 'idle' && kernel.connectionStatus === 'connected';
}"""

JS_ALL_EXECUTED = """() => {
  const prompts = [...document.querySelectorAll('.jp-NotebookPanel:not(.lm-mod-hidden) .jp-CodeCell .jp-InputPrompt')];
  if (prompts.length === 0) return false;
  return prompts.every(p => /\\[\\s*\\d+\\s*\\]/.test(p.textContent));
}"""

JS_TRACEBACKS = """() => [...document.querySelectorAll('.jp-OutputArea-output')]
  .map(e => e.textContent).filter(t => t.includes('Traceback (most recent call last)'))
  .map(t => t.slice(0, 2000))"""


def _dismiss_dialogs(page) -> None:
    """Accept a kernel-selection dialog if one pops up (the notebook names python3, the default)."""
    dialog = page.locator(".jp-Dialog")
    if dialog.count() and dialog.first.is_visible():
        accept = dialog.locator(".jp-mod-accept")
        if accept.count():
            accept.first.click()


def _wait_kernel_idle(page, timeout_s: float) -> None:
    """Wait until the notebook's kernel is connected and idle, accepting any kernel dialog."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        _dismiss_dialogs(page)
        if page.evaluate(JS_KERNEL_IDLE):
            return
        page.wait_for_timeout(500)
    raise TimeoutError(f"the kernel did not become idle within {timeout_s:.0f} s")


def _run_all_cells(page) -> None:
    page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
    page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()


def run_notebook_and_move_slider(page, lab: Lab, notebook: str, shots: Path) -> tuple[str, str]:
    """Open ``notebook``, run it, press the threshold slider's arrow keys; return readouts before/after."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    page.goto(lab.url(notebook), wait_until="domcontentloaded", timeout=60_000)
    page.wait_for_selector(".jp-NotebookPanel .jp-Notebook .jp-Cell", timeout=60_000)
    _wait_kernel_idle(page, 90)

    _run_all_cells(page)
    # Running all cells first marks them [*]; done means every prompt numbered and the kernel idle.
    deadline = time.monotonic() + 150
    while not page.evaluate(f"() => ({JS_ALL_EXECUTED})() && ({JS_KERNEL_IDLE})()"):
        if time.monotonic() > deadline:
            raise TimeoutError("the notebook did not finish running within 150 s")
        _dismiss_dialogs(page)
        page.wait_for_timeout(500)
    tracebacks = page.evaluate(JS_TRACEBACKS)
    assert not tracebacks, f"{notebook} raised in the browser:\n" + "\n---\n".join(tracebacks)

    slider = page.locator(f".{SLIDER_CLASS}").first
    readout = page.locator(f".{READOUT_CLASS}").first
    slider.wait_for(state="visible", timeout=30_000)
    readout.wait_for(state="visible", timeout=30_000)
    slider.scroll_into_view_if_needed()
    page.wait_for_timeout(500)  # let the first render land in the readout
    before = readout.inner_text()
    page.screenshot(path=str(shots / "before.png"))

    # noUiSlider handles take focus and move one step per arrow key, as a user's keyboard would.
    handle = slider.locator(".noUi-handle").first
    handle.focus()
    for _ in range(8):
        handle.press("ArrowRight")
    try:
        page.wait_for_function(
            "([sel, old]) => { const e = document.querySelector(sel); return e && e.innerText !== old; }",
            arg=[f".{READOUT_CLASS}", before], timeout=30_000, polling=250)
    except PlaywrightTimeout:
        # Fall back to typing into the slider's editable readout.
        box = slider.locator(".widget-readout").first
        value = float(box.inner_text())
        box.click()
        page.keyboard.press("Control+A")
        page.keyboard.type(f"{value + 20:g}")
        page.keyboard.press("Enter")
        page.wait_for_function(
            "([sel, old]) => { const e = document.querySelector(sel); return e && e.innerText !== old; }",
            arg=[f".{READOUT_CLASS}", before], timeout=30_000, polling=250)
    page.wait_for_timeout(500)
    after = readout.inner_text()
    page.screenshot(path=str(shots / "after.png"))
    slider.locator("xpath=ancestor::div[contains(@class,'jp-OutputArea-output')][1]").first.screenshot(
        path=str(shots / "widget.png"))
    return before, after


def _contour_area(readout: str) -> float | None:
    m = re.search(r"contour area\s+([\d.]+)\s*px", readout)
    return float(m.group(1)) if m else None


@pytest.mark.timeout(300)
def test_template_explorer_slider_moves_the_readout(lab):
    from playwright.sync_api import sync_playwright

    assert NOTEBOOK.exists(), f"{NOTEBOOK} is missing"
    shots = OUTPUT
    shots.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            try:
                before, after = run_notebook_and_move_slider(page, lab, NOTEBOOK.name, shots)
            except Exception:
                page.screenshot(path=str(shots / "failure.png"))
                (shots / "jupyterlab.log").write_text(lab.log())
                raise
        finally:
            browser.close()
    area_before, area_after = _contour_area(before), _contour_area(after)
    assert area_before is not None, f"no contour area in the readout before the slider moved: {before!r}"
    assert "manual" in after, f"the threshold did not switch to manual: {after!r}"
    # A brighter threshold on a bright probe leaves fewer pixels above it: the area must shrink.
    assert area_after is not None and area_after < area_before, (
        f"moving the threshold slider up did not shrink the contour area: {before!r} -> {after!r}")
