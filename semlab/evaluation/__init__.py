"""The evaluation corpus: scene families with exact ground truth and the Cramér–Rao bound, and its runner.

Every tracking figure semlab reports comes from here (issue 13): :func:`evaluate` runs trackers on
the families of :data:`FAMILIES` for the seeds asked (the test seeds :data:`TEST_SEEDS` by default;
tune on :data:`DEV_SEEDS`), one dask task per (family, seed), and returns one row per family x
seed x tracker; :func:`summarise` makes the per-family table and
:func:`semlab.evaluation.figures.plot_corpus` its figure. The command line is ``semlab evaluate``.

Modules: :mod:`.families` (the generators, the seeds), :mod:`.semireal` (the real needle over
real backgrounds), :mod:`.motion` (probe paths), :mod:`.draws` (parameter ranges),
:mod:`.trackers` (trackers by name), :mod:`.scoring` (per-frame errors, the row's definitions),
:mod:`.runner` (dask), :mod:`.summary` (tables), :mod:`.figures` (matplotlib, imported on use).
"""

from .families import DEV_SEEDS, FAMILIES, FAMILY_NAMES, TEST_SEEDS, make_family_sequence, split_of
from .runner import SchedulerUnreachable, evaluate
from .scoring import COLUMNS, PER_FRAME_COLUMNS
from .summary import summarise, summary_markdown
from .trackers import DEFAULT_TRACKERS, TRACKER_NAMES

__all__ = ["COLUMNS", "DEFAULT_TRACKERS", "DEV_SEEDS", "FAMILIES", "FAMILY_NAMES", "PER_FRAME_COLUMNS",
           "TEST_SEEDS", "TRACKER_NAMES", "SchedulerUnreachable", "evaluate", "make_family_sequence",
           "split_of", "summarise", "summary_markdown"]
