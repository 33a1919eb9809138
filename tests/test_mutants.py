"""A fixed sample of planted bugs in the controller and the sub-pixel step: the tests must catch each.

``make mutate`` runs mutmut over all the core modules (slow, not in CI). This sample runs in CI:
each mutant is one plausible bug (a sign, a swapped coefficient, a reversed condition) applied to a
temporary copy of the package; the tests about that code run against the copy in a subprocess and
must FAIL. The unmutated copy must pass the same tests, so a failure is the mutant's doing.

A mutant is located by its source text anywhere in ``semlab/`` (so a function moved to another
module keeps its mutant); text that no longer occurs, or occurs twice, fails the test by name:
update the mutant with the code, never drop it silently.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONTROL_TESTS = ["tests/test_pid_oracle.py", "tests/test_step_metrics.py"]
SUBPIXEL_TESTS = ["tests/test_subpixel_theory.py", "tests/test_track_steps.py"]

# name: (source text, mutated text, tests that must catch it)
MUTANTS = {
    "pid: derivative filter alpha <-> 1 - alpha": (
        "a * m_prev + (1 - a) * float(measurement)",
        "(1 - a) * m_prev + a * float(measurement)", CONTROL_TESTS),
    "pid: derivative on the raw, not the filtered, measurement": (
        "-self.kd * (self._m_filt - m_prev)",
        "-self.kd * (float(measurement) - m_prev)", CONTROL_TESTS),
    "pid: slew anti-windup applied only when the slew limit does NOT hold": (
        "if slewed != out and self.ki > 0:",
        "if slewed == out and self.ki > 0:", CONTROL_TESTS),
    "pid: slew anti-windup reverted to freezing the integral": (
        "integral = slewed - self._p - self._d",
        "integral = self.integral", CONTROL_TESTS),
    "pid: output-limit back-calculation reversed (lo and hi swapped)": (
        "integral = min(max(integral, lo - self._p - self._d), hi - self._p - self._d)",
        "integral = max(min(integral, lo - self._p - self._d), hi - self._p - self._d)", CONTROL_TESTS),
    "pid: downstream back-calculation reversed": (
        "elif applied < self.output:",
        "elif applied > self.output:", CONTROL_TESTS),
    "step_metrics: 0.5-px band widened to 0.6 px": (
        '(0.5, "0p5px")',
        '(0.6, "0p5px")', CONTROL_TESTS),
    "step_metrics: overshoot sign ignores the step's direction": (
        "sgn = 1.0 if step >= 0 else -1.0",
        "sgn = 1.0", CONTROL_TESTS),
    "subpixel: five-point derivative mask with its outer taps' sign flipped": (
        "np.array([1.0, -8.0, 0.0, 8.0, -1.0], np.float32) / 12.0",
        "np.array([-1.0, -8.0, 0.0, 8.0, 1.0], np.float32) / 12.0", SUBPIXEL_TESTS),
    "subpixel: eq. 9 solved with the residual's sign reversed": (
        "(t - i)[use].astype(np.float64)",
        "(i - t)[use].astype(np.float64)", SUBPIXEL_TESTS),
    "subpixel: Keys kernel a = -0.5 changed in its last tap": (
        "0.5 * t3 - 0.5 * t2])",
        "0.5 * t3 - 0.45 * t2])", SUBPIXEL_TESTS),
    "subpixel: Gauss-Newton inverse composition with the wrong sign in x": (
        "p[0] -= damping * dx",
        "p[0] += damping * dx", SUBPIXEL_TESTS),
    "subpixel: Huber weights inverted (outliers weighted up)": (
        "return c / np.maximum(np.abs(z), c), spread",
        "return np.maximum(np.abs(z), c) / c, spread", SUBPIXEL_TESTS),
    "subpixel: line whitening adds the previous pixel instead of subtracting it": (
        "np.float32(-rho)",
        "np.float32(rho)", SUBPIXEL_TESTS),
}


def _copy(tmp: Path) -> Path:
    work = tmp / "copy"
    shutil.copytree(ROOT / "semlab", work / "semlab", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "tests", work / "tests", ignore=shutil.ignore_patterns("__pycache__", "test_mutants.py"))
    shutil.copy(ROOT / "pyproject.toml", work / "pyproject.toml")
    return work


def _run(work: Path, tests: list[str]) -> subprocess.CompletedProcess:
    # cwd and PYTHONPATH point at the copy, so `import semlab` finds it before the installed one
    env = {**os.environ, "PYTHONPATH": str(work), "PYTHONDONTWRITEBYTECODE": "1"}
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-m", "not slow", *tests]
    return subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=300, check=False)


def _apply(work: Path, name: str, before: str, after: str) -> None:
    hits = [(p, p.read_text()) for p in sorted((work / "semlab").rglob("*.py"))]
    hits = [(p, text) for p, text in hits if before in text]
    count = sum(text.count(before) for _, text in hits)
    assert count == 1, f"mutant {name!r}: its source text occurs {count} times in semlab/; update the mutant"
    path, text = hits[0]
    path.write_text(text.replace(before, after))


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    work = _copy(tmp_path_factory.mktemp("pristine"))
    env = {**os.environ, "PYTHONPATH": str(work)}
    where = subprocess.run([sys.executable, "-c", "import semlab; print(semlab.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True).stdout.strip()
    assert Path(where).resolve().is_relative_to(work.resolve()), f"the copy is not what gets imported: {where}"
    for tests in (CONTROL_TESTS, SUBPIXEL_TESTS):
        run = _run(work, tests)
        assert run.returncode == 0, f"the unmutated copy fails {tests}:\n{run.stdout[-3000:]}"
    return work


@pytest.mark.mutants
@pytest.mark.parametrize("name", list(MUTANTS))
def test_planted_bug_is_caught(name, pristine, tmp_path):
    before, after, tests = MUTANTS[name]
    work = tmp_path / "mutant"
    shutil.copytree(pristine, work)
    _apply(work, name, before, after)
    run = _run(work, tests)
    # pytest's exit code 1 is "tests failed"; 2-5 would be an error of the harness, not a catch
    assert run.returncode == 1, f"mutant {name!r} survived {tests} (exit {run.returncode}):\n{run.stdout[-2000:]}"
