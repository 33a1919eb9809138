"""semlab.environment.describe: the provenance record of ``semlab track``/``evaluate`` and save_run."""

import platform
import sys

import numpy as np

from semlab.environment import describe


def test_describe_records_python_platform_and_imported_libraries():
    env = describe()
    assert env["python"] == platform.python_version()
    assert env["platform"] == platform.platform()
    assert env["numpy"] == np.__version__  # imported here, so it must be recorded


def test_describe_records_extra_modules_only_when_imported():
    assert "semlab_not_a_module" not in describe(extra=("semlab_not_a_module",))
    assert "semlab_not_a_module" not in sys.modules  # describing imports nothing
    env = describe(extra=("semlab",))
    assert env["semlab"] == sys.modules["semlab"].__version__
