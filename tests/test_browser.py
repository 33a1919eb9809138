"""The workbench in a real browser: JupyterLab driven by Debian's chromium through Playwright.

The test starts JupyterLab on a free localhost port (token auth, no browser, temporary config and a
temporary copy of ``notebooks/`` so that nothing the browser saves lands in git), opens
``01_contour_template.ipynb``, runs all cells from the *Run* menu and waits for the kernel to go idle (once, for
both tests). Then it moves the template explorer's threshold slider with the keyboard and asserts that the
displayed contour readout changes, and it clicks the explorer's frame overview (the paper's "click near the
probe tip", through ipyevents) at known places -- at the overview's own size and after CSS has shrunk it --
and asserts that the readout shows the 200x200 ROI around each click, shifted inside the frame at the
border. Screenshots land in ``test-output/browser/``.

For every notebook with a conclusion it opens the notebook, runs it and saves a screenshot of its "What we see"
section, as JupyterLab shows it, in ``test-output/browser/conclusions/<notebook>.png`` (the paths are printed and
listed in ``conclusions/index.txt``). Last, it saves notebook 01, shuts its kernel down and reopens it: the widgets
must come back from the state saved in the notebook, without "Error displaying widget: model not found".

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
OVERVIEW_CLASS = "semlab-overview"
CLICK_X_CLASS, CLICK_Y_CLASS = "semlab-click-x", "semlab-click-y"
ROI_SIZE = 200   # the notebook's ROI_SIZE: the paper's 200x200 px at 3,000x

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

    def url(self, notebook: str, *, workspace: str | None = None) -> str:
        """The notebook's URL; in a workspace of its own (no tabs restored from earlier pages) if named."""
        where = f"workspaces/{workspace}/tree" if workspace else "tree"
        return f"{self.base}/lab/{where}/{notebook}?token={self.token}" + ("&reset" if workspace else "")

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


def open_and_run(page, lab: Lab, notebook: str) -> None:
    """Open ``notebook``, run all its cells from the menu, and fail on any traceback."""
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


def move_slider(page, shots: Path) -> tuple[str, str]:
    """Press the threshold slider's arrow keys; return the readouts before and after."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

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


JS_READOUT_CHANGED = """([sel, old]) => { const e = document.querySelector(sel); return e && e.innerText !== old; }"""

# Record where a click lands the way ipyevents 2 measures it (``relativeX = round(clientX - rect.left)`` and the
# bounding rectangle), so the test can tell what the kernel was sent.
JS_RECORD_CLICKS = """(el) => {
  window.__semlabClicks = [];
  el.addEventListener('click', e => {
    const r = el.getBoundingClientRect();
    window.__semlabClicks.push({x: Math.round(e.clientX - r.left), y: Math.round(e.clientY - r.top),
                                width: r.width, height: r.height});
  });
}"""


def _slider_max(page, cls: str) -> int | None:
    """The ``max`` of an ipywidgets IntSlider, read from its noUiSlider handle."""
    handle = page.locator(f".{cls} .noUi-handle").first
    value = handle.get_attribute("aria-valuemax") if handle.count() else None
    return round(float(value)) if value else None


def _roi_in(readout: str) -> tuple[int, ...] | None:
    m = re.search(r"ROI\s*\((\d+),\s*(\d+),\s*(\d+),\s*(\d+)\)", readout)
    return tuple(int(v) for v in m.groups()) if m else None


def click_overview(page, fraction: tuple[float, float], shots: Path, name: str) -> dict:
    """Click the overview at ``fraction`` of its displayed width and height; wait for the ROI readout to change.

    Returns the click as the browser measured it (``x, y, width, height``, CSS px) and the readouts.
    """
    overview = page.locator(f".{OVERVIEW_CLASS}").first
    readout = page.locator(f".{READOUT_CLASS}").first
    overview.scroll_into_view_if_needed()
    box = overview.bounding_box()
    before = readout.inner_text()
    n = page.evaluate("() => window.__semlabClicks.length")
    overview.click(position={"x": fraction[0] * box["width"], "y": fraction[1] * box["height"]})
    page.wait_for_function(JS_READOUT_CHANGED, arg=[f".{READOUT_CLASS}", before], timeout=30_000, polling=250)
    page.wait_for_timeout(300)
    clicks = page.evaluate("() => window.__semlabClicks")
    assert len(clicks) == n + 1, f"the overview saw {len(clicks) - n} clicks, expected one"
    page.screenshot(path=str(shots / f"click-{name}.png"))
    return {**clicks[-1], "before": before, "after": readout.inner_text()}


def _contour_area(readout: str) -> float | None:
    m = re.search(r"contour area\s+([\d.]+)\s*px", readout)
    return float(m.group(1)) if m else None


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium, driven by Playwright (one per module: the sync API allows one at a time)."""
    from playwright.sync_api import sync_playwright

    OUTPUT.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


@pytest.fixture(scope="module")
def notebook_page(lab, browser):
    """A chromium page showing notebook 01, run to the end in JupyterLab (shared by the tests below)."""
    assert NOTEBOOK.exists(), f"{NOTEBOOK} is missing"
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.semlab_console = []   # every console message of the page, for the reopening test
    page.on("console", lambda msg: page.semlab_console.append(msg.text))
    try:
        open_and_run(page, lab, NOTEBOOK.name)
    except Exception:
        _save_failure(page, lab)
        raise
    yield page
    page.close()


def _save_failure(page, lab: Lab) -> None:
    page.screenshot(path=str(OUTPUT / "failure.png"))
    (OUTPUT / "jupyterlab.log").write_text(lab.log())


@pytest.mark.timeout(300)
def test_template_explorer_slider_moves_the_readout(notebook_page, lab):
    try:
        before, after = move_slider(notebook_page, OUTPUT)
    except Exception:
        _save_failure(notebook_page, lab)
        raise
    area_before, area_after = _contour_area(before), _contour_area(after)
    assert area_before is not None, f"no contour area in the readout before the slider moved: {before!r}"
    assert "manual" in after, f"the threshold did not switch to manual: {after!r}"
    # A brighter threshold on a bright probe leaves fewer pixels above it: the area must shrink.
    assert area_after is not None and area_after < area_before, (
        f"moving the threshold slider up did not shrink the contour area: {before!r} -> {after!r}")


@pytest.mark.timeout(300)
def test_a_click_on_the_overview_cuts_the_roi_around_it(notebook_page, lab):
    from semlab.roi import clip_window
    from semlab.widgets import display_to_frame

    page = notebook_page
    overview = page.locator(f".{OVERVIEW_CLASS}").first
    try:
        overview.wait_for(state="visible", timeout=30_000)
        overview.evaluate(JS_RECORD_CLICKS)
        # The frame size, from the click sliders' ranges (0 .. cols - 1, 0 .. rows - 1).
        cols, rows = (_slider_max(page, c) for c in (CLICK_X_CLASS, CLICK_Y_CLASS))
        assert cols and rows, "could not read the frame size from the click sliders"
        cols, rows = cols + 1, rows + 1
        clicks = [("inside", (0.3, 0.4), None)]
        # CSS shrinks the overview to 60 %: the same conversion must still find the frame point.
        clicks.append(("css-scaled", (0.8, 0.25), "264px"))
        # The bottom-right corner: the ROI is shifted into the frame, not cut short.
        clicks.append(("corner", (0.99, 0.99), None))
        results = []
        for name, fraction, css_width in clicks:
            if css_width:
                overview.evaluate("(el, w) => { el.style.width = w; }", css_width)
                page.wait_for_timeout(300)
            results.append((name, fraction, click_overview(page, fraction, OUTPUT, name)))
    except Exception:
        _save_failure(page, lab)
        raise

    for name, fraction, c in results:
        roi = _roi_in(c["after"])
        assert roi is not None, f"{name}: no ROI in the readout {c['after']!r}"
        assert roi != _roi_in(c["before"]), f"{name}: the click did not move the ROI: {c['before']!r}"
        # What the kernel was sent -> the frame point -> the paper's 200x200 ROI around it.
        x, y = display_to_frame((c["x"], c["y"]), (c["width"], c["height"]), (rows, cols))
        expected = clip_window(round(x), round(y), ROI_SIZE, ROI_SIZE, (rows, cols))
        assert roi == expected, f"{name}: clicked {c}, frame ({x:.1f}, {y:.1f}); readout {c['after']!r}"
        # Independently of the conversion: the ROI is centred where the click is on the frame, within one
        # CSS pixel (the browser reports whole pixels) and the slider's rounding, unless shifted at the border.
        tol = max(cols / c["width"], rows / c["height"]) + 1.0
        centre = (roi[0] + (ROI_SIZE - 1) / 2, roi[1] + (ROI_SIZE - 1) / 2)
        for axis, f, n in ((0, fraction[0], cols), (1, fraction[1], rows)):
            target = f * n - 0.5
            inside = ROI_SIZE / 2 <= target <= n - ROI_SIZE / 2
            if inside:
                assert abs(centre[axis] - target) <= tol, (name, axis, centre, target, tol)
            else:
                assert roi[axis] in (0, n - ROI_SIZE), (name, axis, roi)
    scaled = {name: c for name, _, c in results}["css-scaled"]
    assert scaled["width"] == pytest.approx(264, abs=1), f"the overview was not shrunk by CSS: {scaled}"
    assert _roi_in(results[-1][2]["after"]) == (cols - ROI_SIZE, rows - ROI_SIZE, ROI_SIZE, ROI_SIZE)


# --- the notebooks' conclusions, as JupyterLab shows them ----------------------------------------------

CONCLUSIONS = OUTPUT / "conclusions"
EXECUTED = ROOT / "test-output" / "notebooks"   # where tests/test_notebooks.py leaves the executed copies
CONCLUDED = [p for p in sorted((ROOT / "notebooks").glob("*.ipynb"))
             if "## What we see" in p.read_text(encoding="utf-8")]
VISIBLE_CELLS = ".jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook .jp-Cell"


def _api(lab: Lab, path: str, method: str = "GET"):
    req = urllib.request.Request(f"{lab.base}/api/{path}?token={lab.token}", method=method)
    with urllib.request.urlopen(req, timeout=30) as r:
        body = r.read()
    return json.loads(body) if body else None


def _shut_down_kernels(lab: Lab, under: str = "") -> None:
    """Shut down the kernels of the sessions whose notebook lies ``under`` a folder ('' for all)."""
    for session in _api(lab, "sessions"):
        if session["path"].startswith(under):
            _api(lab, f"sessions/{session['id']}", method="DELETE")


def _shown_copy(path: Path, lab: Lab) -> tuple[str, bool]:
    """The notebook JupyterLab opens for the screenshot: the executed copy when it is fresh, else the source.

    Running every notebook again in the browser would double their CI time; after ``tests/test_notebooks.py``
    (run it first, or ``make test`` twice) the picture shows the conclusion with the numbers above it.
    """
    executed = EXECUTED / path.name
    fresh = executed.exists() and executed.stat().st_mtime >= path.stat().st_mtime
    folder = lab.root / "shown"
    folder.mkdir(exist_ok=True)
    shutil.copy(executed if fresh else path, folder / path.name)
    return f"shown/{path.name}", fresh


@pytest.mark.timeout(180)
@pytest.mark.parametrize("path", CONCLUDED, ids=lambda p: p.name)
def test_the_conclusion_shows_in_jupyterlab(path, lab, browser):
    CONCLUSIONS.mkdir(parents=True, exist_ok=True)
    shown, executed = _shown_copy(path, lab)
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    try:
        page.goto(lab.url(shown, workspace=path.stem), wait_until="domcontentloaded", timeout=60_000)
        n_cells = len(json.loads(path.read_text(encoding="utf-8"))["cells"])
        page.wait_for_function("([sel, n]) => document.querySelectorAll(sel).length === n",
                               arg=[VISIBLE_CELLS, n_cells], timeout=60_000, polling=250)
        _dismiss_dialogs(page)
        page.wait_for_timeout(500)   # let the notebook settle (the active cell scrolls into view)
        cell = page.locator(VISIBLE_CELLS).last
        cell.scroll_into_view_if_needed()
        heading = cell.locator(".jp-RenderedMarkdown h2")
        heading.wait_for(state="visible", timeout=30_000)
        assert heading.inner_text().strip().startswith("What we see"), heading.inner_text()
        assert len(cell.inner_text().split()) >= 60, "the conclusion rendered as a stub"
        if executed:   # the table of numbers the conclusion rests on, in the cell before it
            numbers = page.locator(VISIBLE_CELLS).nth(-2)
            assert "RESULTS" in numbers.inner_text()
            top, bottom = numbers.bounding_box(), cell.bounding_box()
            height = int(bottom["y"] + bottom["height"] - top["y"]) + 250   # + menu, toolbar, status bar
            page.set_viewport_size({"width": 1400, "height": max(1000, min(height, 4000))})
            numbers.scroll_into_view_if_needed()
        page.wait_for_timeout(500)
        shot = CONCLUSIONS / f"{path.stem}.png"
        page.screenshot(path=str(shot))
        cell.screenshot(path=str(CONCLUSIONS / f"{path.stem}-text.png"))
        with open(CONCLUSIONS / "index.txt", "a", encoding="utf-8") as index:
            index.write(f"{shot}{'' if executed else '  (conclusion only: no executed copy yet)'}\n")
        print(f"conclusion of {path.name}: {shot}")
    except Exception:
        page.screenshot(path=str(OUTPUT / f"failure-{path.stem}.png"))
        (OUTPUT / "jupyterlab.log").write_text(lab.log())
        raise
    finally:
        page.close()
        _shut_down_kernels(lab, under="shown/")


# --- reopening a saved notebook (must stay the last test: it restarts notebook 01's kernel) -----------

MODEL_NOT_FOUND = "model not found"


@pytest.mark.timeout(300)
def test_a_saved_notebook_reopens_with_its_widgets(notebook_page, lab):
    page = notebook_page
    name = NOTEBOOK.name
    try:
        before = _api(lab, f"contents/{name}")["last_modified"]
        # JupyterLab's own save command on the notebook (what Ctrl+S runs), not a menu hunt
        page.evaluate("() => window.jupyterapp.commands.execute('docmanager:save')")
        deadline = time.monotonic() + 30
        while _api(lab, f"contents/{name}")["last_modified"] == before:
            assert time.monotonic() < deadline, "the notebook was not saved within 30 s"
            page.wait_for_timeout(300)
        saved = _api(lab, f"contents/{name}")["content"]
        views = {o["data"]["application/vnd.jupyter.widget-view+json"]["model_id"]
                 for c in saved["cells"] if c["cell_type"] == "code" for o in c.get("outputs", [])
                 if "application/vnd.jupyter.widget-view+json" in o.get("data", {})}
        assert views, "the saved notebook holds no widget outputs to reopen"
        state = saved["metadata"].get("widgets", {}).get("application/vnd.jupyter.widget-state+json", {})
        # The cause of "model not found": widget outputs saved, their models' state not (saveState false).
        assert views <= set(state.get("state", {})), (
            "the notebook was saved without its widgets' state (JupyterLab's saveState setting): "
            f"{len(views - set(state.get('state', {})))} widget outputs would reopen as 'model not found'")

        _shut_down_kernels(lab)                    # as after closing JupyterLab: the models are gone
        seen = len(page.semlab_console)
        page.reload(wait_until="domcontentloaded")
        page.wait_for_selector(".jp-NotebookPanel .jp-Notebook .jp-Cell", timeout=60_000)
        _wait_kernel_idle(page, 90)
        # Either the explorer is rebuilt from the saved state, or its output says the model is missing.
        page.wait_for_function(
            "([cls, msg]) => document.querySelector('.' + cls) !== null || document.body.innerText.includes(msg)",
            arg=[OVERVIEW_CLASS, MODEL_NOT_FOUND], timeout=60_000, polling=250)
        page.wait_for_timeout(3000)               # the manager gives up on a missing model after 2 s
        overview = page.locator(f".{OVERVIEW_CLASS}").first
        if overview.count():
            overview.scroll_into_view_if_needed()
        page.screenshot(path=str(OUTPUT / "reopened.png"))
    except Exception:
        _save_failure(page, lab)
        raise
    text = page.locator(".jp-NotebookPanel").first.inner_text()
    assert MODEL_NOT_FOUND not in text, "a reopened widget output says 'Error displaying widget: model not found'"
    logged = [m for m in page.semlab_console[seen:] if MODEL_NOT_FOUND in m]
    assert not logged, f"the browser logged: {logged[:3]}"
    assert overview.count() and overview.evaluate("el => el.tagName === 'IMG' && el.naturalWidth > 0"), (
        "the explorer's overview did not come back from the saved state")
