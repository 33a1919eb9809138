"""Real instruments and recordings behind semlab's protocols (:mod:`semlab.protocols`).

- :mod:`.fibsem`: a FIB/SEM through OpenFIBSEM (``pip install "semlab[fibsem]"``):
  :class:`~.fibsem.FibsemMicroscope` (frames) and :class:`~.fibsem.FibsemManipulator` (the needle).
- :mod:`.demo`: semlab's simulated needle inside OpenFIBSEM's offline ``DemoMicroscope``, with
  ground truth (tests, the notebook on a machine without a microscope).
- :mod:`.replay`: :class:`~.replay.ReplayMicroscope` plays a recording at its frame period.
- :mod:`.record`: a servo run saved with its provenance; :mod:`.picker`: click a target.

Nothing here is imported by ``import semlab``; only :mod:`.fibsem` and :mod:`.demo` need ``fibsem``.
"""
