"""What a result was computed with: the versions a provenance sidecar records.

``semlab track``, ``semlab evaluate`` and :func:`semlab.instruments.record.save_run` write this record
next to their CSVs, so a number can be traced to the Python, platform and libraries that produced it.
"""

from __future__ import annotations

import platform
import sys

__all__ = ["describe"]

#: The libraries the tracking and imaging maths runs on: recorded whenever they are imported.
CORE_MODULES = ("numpy", "scipy", "pandas", "cv2", "skimage", "tifffile")


def describe(extra: tuple[str, ...] = ()) -> dict:
    """The Python version, the platform and the versions of the imported core libraries.

    Parameters
    ----------
    extra : tuple of str
        More module names to record (e.g. ``("semlab", "fibsem")``), each only if already imported:
        describing the environment never imports anything new.

    Returns
    -------
    dict
        JSON-ready ``{"python": ..., "platform": ..., "<module>": "<version>", ...}``; a module
        without ``__version__`` is recorded as ``"?"``.
    """
    env = {"python": platform.python_version(), "platform": platform.platform()}
    for name in (*CORE_MODULES, *extra):
        mod = sys.modules.get(name)
        if mod is not None:
            env[name] = getattr(mod, "__version__", "?")
    return env
