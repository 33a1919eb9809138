"""The tracker on real FIB/SEM frames: a tungsten needle stepping onto a lamella (AutoLiftout,
MIT-licensed, see ../shared/real-sem/PROVENANCE.md), frames 0-10 of ``contact_brightness_seq``
in their natural order. From frame 6 the needle touches the lamella and the brightness jumps.

The reference displacements of frames 0-5 (tests/data/track_contact_consensus.csv) come from two
independent peers on the needle alone and from the needle's front-face edge, never from semlab's
tracker; the file says how.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from semlab.tracking import Tracker


def _shared() -> Path | None:
    for base in (Path(__file__).resolve().parents[2] / "shared", Path("/work/shared")):
        if (base / "real-sem" / "autoliftout" / "contact_brightness_seq").is_dir():
            return base
    return None


SHARED = _shared()
pytestmark = pytest.mark.skipif(SHARED is None, reason="../shared/real-sem (the real FIB/SEM frames) is not beside the repo")
ROI = (400, 150, 200, 200)  # 200x200 around the needle's tip corner in frame 0
#: Notebook 07's ROI: 200x200 around where an operator clicks near the tip. At contact (frame 5) the
#: window's registration fails and a whole-frame search finds a poor match of the trench's texture,
#: which must lose to the re-acquisition of the needle in the window.
CLICK_ROI = (380, 170, 200, 200)
#: A frame-to-frame step (px) after contact beyond which the tracker has locked onto something else:
#: the approach's largest step (9.7 px) plus the rigid model's misfit of the bending needle (2 px).
FALSE_LOCK_STEP_PX = 12.0


@pytest.fixture(scope="module")
def frames():
    folder = SHARED / "real-sem" / "autoliftout" / "contact_brightness_seq"
    out = [cv2.imread(str(folder / f"liftout_contact_brightness_{k}_ib.png"), cv2.IMREAD_UNCHANGED) for k in range(11)]
    assert all(f is not None and f.ndim == 2 for f in out)
    return out


@pytest.fixture(scope="module")
def reference():
    return pd.read_csv(Path(__file__).parent / "data" / "track_contact_consensus.csv", comment="#")


def _run(frames, roi=ROI):
    t = Tracker()
    first = t.init(frames[0], roi)
    rows = [(0, 0.0, 0.0, True)]
    for k in range(1, len(frames)):
        r = t.update(frames[k])
        rows.append((k, r.x - first.x, r.y - first.y, r.ok))
    return pd.DataFrame(rows, columns=["frame", "dx", "dy", "ok"])


def test_needle_followed_while_it_approaches(frames, reference):
    # Frames 0-4: the needle steps ~7-9 px per frame towards the lamella, not yet touching.
    res = _run(frames).set_index("frame")
    ref = reference.set_index("frame")
    for k in range(5):
        assert res.loc[k, "ok"], f"frame {k} flagged lost"
        err = np.hypot(res.loc[k, "dx"] - ref.loc[k, "dx"], res.loc[k, "dy"] - ref.loc[k, "dy"])
        assert err <= 1.5, f"frame {k}: {err:.2f} px from the consensus"


@pytest.mark.parametrize("roi", [ROI, CLICK_ROI], ids=["tip-corner", "click"])
def test_needle_followed_through_contact(frames, reference, roi):
    # The full requirement: no loss flag in all 11 frames, and frame 5 (contact) within
    # 1.5 px of the consensus. From frame 6 the brightness jumps and the needle, now touching the
    # lamella, is lifted: it keeps moving, by about its approach steps (at most 9.7 px per frame) give or
    # take the rigid model's misfit once it bends (up to 3 px, tests/data/track_contact_consensus.csv),
    # so a step beyond FALSE_LOCK_STEP_PX between frames would be a false lock, not the needle (the
    # false lock this guards against jumped 43 px).
    res = _run(frames, roi).set_index("frame")
    assert res["ok"].all(), f"frames flagged lost: {res.index[~res['ok']].tolist()}"
    ref = reference.set_index("frame")
    assert np.hypot(res.loc[5, "dx"] - ref.loc[5, "dx"], res.loc[5, "dy"] - ref.loc[5, "dy"]) <= 1.5
    steps = np.hypot(np.diff(res["dx"].to_numpy()), np.diff(res["dy"].to_numpy()))
    assert steps[5:].max() < FALSE_LOCK_STEP_PX, f"frame-to-frame steps after contact: {np.round(steps[5:], 2)}"
