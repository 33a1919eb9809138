"""The tracker's per-frame uncertainty (sigma_x, sigma_y) and its flags, and one answer whatever the
gray-level encoding of the frames (issue 14)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import erf
from skimage import img_as_float

import semlab
from semlab.evaluation import make_family_sequence
from semlab.evaluation.scoring import frame_errors
from semlab.tracking import METHODS, Tracker, ic, track, uncertainty
from semlab.tracking.ic import ICMethod
from semlab.tracking.options import LossOptions
from semlab.tracking.trust import DOUBT_FRAMES, Judge
from semlab.tracking.uncertainty import (
    AMBIGUOUS_JUMP_PX,
    MAX_TEXTURED_SCORE_DROP,
    MIN_RESOLVED_CONTRAST,
    MODEL_ERROR_PER_GAIN_PX,
    MODEL_ERROR_PER_MISFIT_PX,
    MODEL_ERROR_PX,
    RECENT_FRAMES,
    SIGMA_LIMIT_PX,
    TYPICAL_MATCH_SCORE,
    UNVOUCHED_JUMP_PX,
    YOUNG_TEMPLATE_FRAMES,
    YOUNG_TEMPLATE_INFLATION,
    RecentPrecision,
    ambiguous_jump,
    least_squares_covariance,
    model_error,
    slid_on_texture,
    young_template_inflation,
)

ROI = (60, 40, 120, 120)
CENTRE = (ROI[0] + (ROI[2] - 1) / 2, ROI[1] + (ROI[3] - 1) / 2)


def wedge_frame(dx, dy, *, noise=0.0, seed=0, shape=(200, 260), blur=1.2):
    """A bright blunt wedge (tip near (120, 100), pointing +x) on a flat background, analytic."""
    yy, xx = np.mgrid[:shape[0], :shape[1]].astype(np.float64)
    u, v = xx - 120.0 - dx, yy - 100.0 - dy
    half = math.radians(14.0)
    d = np.maximum(np.abs(v) * math.cos(half) + u * math.sin(half), u - 6.0)  # signed distance, flat end 6 px ahead
    img = 50.0 + 130.0 * 0.5 * (1 - erf(d / (math.sqrt(2) * blur)))
    if noise:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    return img.astype(np.float32)


# --------------------------------------------------------------------------- the columns and the flags
def test_sigma_columns_nan_exactly_when_not_ok():
    frames = [wedge_frame(0.3 * k, 0.1 * k, noise=4.0, seed=k) for k in range(8)]
    frames[4] = np.full_like(frames[4], np.nan)  # an unusable frame: flagged, no sigma
    df = track(frames, ROI)
    assert list(df.columns[-2:]) == ["sigma_x", "sigma_y"]
    ok = df["ok"].to_numpy()
    assert not ok[4] and ok[[1, 2, 3, 5, 6, 7]].all()
    assert np.isnan(df.loc[~df.ok, ["sigma_x", "sigma_y"]].to_numpy()).all()
    assert np.isfinite(df.loc[df.ok, ["sigma_x", "sigma_y"]].to_numpy()).all()


def test_sigma_follows_the_noise_as_theory_says():
    # White noise of sd s on a fixed wedge: the shift's Fisher information is sum(grad^2)/s^2, so
    # sigma scales with s; the fit measures s from its own residuals. Across the wedge (y, its flanks'
    # direction), noise 2 -> 8 gray levels: 4x, within 20 % (the residual variance of ~1000 band
    # pixels is known to a few %, the median of 5 frames' sigma to ~10 %).
    def median_sigma_y(noise):
        # A still probe: the fits alone (no model error is added before the object has moved).
        frames = [wedge_frame(0.0, 0.0, noise=noise, seed=k) for k in range(6)]
        df = track(frames, ROI, template_frames=1, max_sigma=None)
        return float(np.median(df["sigma_y"].iloc[1:]))

    assert 3.2 < median_sigma_y(8.0) / median_sigma_y(2.0) < 4.8


def test_sigma_along_the_weak_direction_covers_the_scatter_at_high_noise():
    # Along the wedge's axis only the apex tells x, and a one-frame template's gradients count its own
    # noise as information: the fit alone said 0.14 px at noise 16 where 40 frames scatter by 0.29 px.
    # Against a template of fewer than YOUNG_TEMPLATE_FRAMES frames the reported sigma is
    # YOUNG_TEMPLATE_INFLATION times the fit's, which covers the scatter.
    frames = [wedge_frame(0.0, 0.0, noise=16.0, seed=k) for k in range(41)]
    df = track(frames, ROI, template_frames=1, max_sigma=None)
    scatter = float(np.std(df["x"].iloc[1:]))
    assert float(np.median(df["sigma_x"].iloc[1:])) >= 0.8 * scatter


def test_sigma_covers_the_scatter_of_a_noisy_still_probe():
    # 40 frames of a still wedge under white noise: the one-frame template's noise is in every
    # answer (a common offset, which the origin's covariance does not carry with template_frames=1)
    # so the frame-to-frame scatter is what sigma must cover: 95 % ellipses hold 80-100 % of the
    # frames (binomial sampling error of 40 frames: ±7 %, and sigma is built from a noisy template).
    frames = [wedge_frame(0.0, 0.0, noise=10.0, seed=k) for k in range(41)]
    df = track(frames, ROI, max_sigma=None)
    ex, ey = df["x"] - CENTRE[0], df["y"] - CENTRE[1]
    ex, ey = (ex - ex[1:].mean())[1:], (ey - ey[1:].mean())[1:]
    inside = (ex / df["sigma_x"][1:]) ** 2 + (ey / df["sigma_y"][1:]) ** 2 <= 5.991
    assert 0.8 <= inside.mean() <= 1.0


def test_a_frame_whose_data_allow_too_little_is_flagged_and_followed():
    # Noise so strong that one frame cannot place the wedge within SIGMA_LIMIT_PX: ok=False with the
    # reason, and the tracker still follows (the next quiet frame is ok, on the probe).
    quiet = [wedge_frame(0.5 * k, 0.0, noise=2.0, seed=k) for k in range(6)]
    loud = wedge_frame(3.0, 0.0, noise=120.0, seed=99)
    frames = quiet + [loud] + [wedge_frame(3.5, 0.0, noise=2.0, seed=7)]
    t = Tracker(template_frames=1)
    t.init(frames[0], ROI)
    results = [t.update(f) for f in frames[1:]]
    flagged = results[5]
    assert not flagged.ok and "too uncertain" in flagged.reason and math.isnan(flagged.sigma_x)
    last = results[6]
    assert last.ok and abs(last.x - CENTRE[0] - 3.5) < 0.2
    # max_sigma=None reports it instead (a user who accepts the uncertainty).
    t = Tracker(template_frames=1, max_sigma=None)
    t.init(frames[0], ROI)
    r = [t.update(f) for f in frames[1:]][5]
    assert r.ok and r.sigma_x > SIGMA_LIMIT_PX


def test_a_frame_is_credited_no_better_than_the_recent_frames_median():
    judge = RecentPrecision()
    # Fewer than three known: the frame's own.
    assert judge.judged((0.40, 0.10)) == (0.40, 0.10)
    assert judge.judged((0.45, 0.12)) == (0.45, 0.12)
    # Third, its own included: medians 0.40 (of 0.40, 0.45, 0.20) and 0.11 (of 0.10, 0.12, 0.11).
    assert judge.judged((0.20, 0.11)) == pytest.approx((0.40, 0.11))
    # A frame with no precision passes through and is not recorded.
    assert judge.judged((float("nan"), 0.1))[1] == 0.1
    # x: median of 0.40, 0.45, 0.20, 0.30 is 0.35; y: median 0.115 is under its own 0.13.
    assert judge.judged((0.30, 0.13)) == pytest.approx((0.35, 0.13))
    # The window forgets: after RECENT_FRAMES sharp frames, a sharp frame is its own again.
    for _ in range(RECENT_FRAMES):
        judge.judged((0.10, 0.05))
    assert judge.judged((0.10, 0.05)) == (0.10, 0.05)


def test_a_sharp_track_is_never_judged_too_uncertain():
    judge = RecentPrecision()
    track = [(0.12, 0.05), (0.10, 0.04), (0.15, 0.06), (0.09, 0.05), (0.11, 0.07), (0.08, 0.03)]
    for own in track:
        judged = judge.judged(own)
        assert judged[0] >= own[0] and judged[1] >= own[1]
        assert max(judged) <= SIGMA_LIMIT_PX


@pytest.mark.slow
def test_a_thin_needle_at_low_dose_is_not_reported_ok_on_noise_blobs():
    # Development seed 114 of the thin low-dose needle: frame 0's contour takes in noise blobs and
    # the fit holds on them; the few frames whose own precision dips under SIGMA_LIMIT_PX were 7-25 px
    # off. Judged by the recent frames' precision, none of its ok frames is more than 1 px off.
    seq = make_family_sequence("thin_low_dose", 114)
    errors = frame_errors(track(seq.frames, seq.roi), seq.truth, seq.roi)
    ok = errors[errors["ok"] & (errors["frame"] > 0)]
    assert not (np.hypot(ok["ex"], ok["ey"]) > 1.0).any()


def test_the_contrast_is_measured_against_the_smoothed_noise():
    # The same wedge at twice the noise stands half as many noise standard deviations above its
    # background (the noise is measured on the frame, so within its estimate's scatter); a noiseless
    # frame (its noise estimate's floor) stands far above the limit, and an infinite ratio is resolved.
    def contrast_noise(noise):
        t = Tracker()
        t.init(wedge_frame(0.0, 0.0, noise=noise, seed=1), ROI)
        return t.contrast_noise

    assert contrast_noise(4.0) / contrast_noise(8.0) == pytest.approx(2.0, rel=0.1)
    assert contrast_noise(0.0) > 100 * MIN_RESOLVED_CONTRAST and not uncertainty.unresolved(math.inf)
    assert uncertainty.unresolved(MIN_RESOLVED_CONTRAST - 0.01) and not uncertainty.unresolved(MIN_RESOLVED_CONTRAST)
    assert uncertainty.unresolved(float("nan"))


def test_an_unresolved_object_flags_every_answer_and_is_followed():
    # The same frames, the limit set above frame 0's measured contrast: every answer is flagged with
    # the reason, none has a position or a sigma, and the tracker follows the wedge exactly as
    # without the limit (the flag judges, it does not steer).
    frames = [wedge_frame(0.5 * k, 0.2 * k, noise=4.0, seed=k) for k in range(8)]
    free = Tracker(min_resolved_contrast=None)
    free.init(frames[0], ROI)
    judged = Tracker(min_resolved_contrast=2.0 * free.contrast_noise)
    judged.init(frames[0], ROI)
    for frame in frames[1:]:
        trusted, flagged = free.update(frame), judged.update(frame)
        assert trusted.ok and not flagged.ok and flagged.reason.startswith("unresolved")
        assert math.isnan(flagged.x) and math.isnan(flagged.sigma_x)
        assert np.array_equal(judged.shift, free.shift)
    # The default limit does not flag this wedge (its contrast is far above it).
    assert free.contrast_noise > 2 * MIN_RESOLVED_CONTRAST
    assert track(frames, ROI)["ok"].all()


@pytest.mark.slow
def test_a_thin_needle_not_resolved_above_the_noise_is_flagged_not_followed_silently():
    # Spare seed 243 of the thin low-dose needle (not a test seed): frame 0's needle stands about 5 noise
    # standard deviations above its background. Its Otsu region holds the substrate around it, which the
    # substrate cut takes off (the band left is then too uncertain for any frame to be reported ok); with
    # the region uncut and without the limit, 7 of its frames are reported ok more than 1 px off, their
    # precision under SIGMA_LIMIT_PX. With the limit, none is ok.
    seq = make_family_sequence("thin_low_dose", 243)
    t = Tracker()
    t.init(seq.frames[0], seq.roi)
    assert t.contrast_noise < MIN_RESOLVED_CONTRAST
    assert not track(seq.frames, seq.roi)["ok"].iloc[1:].any()
    assert not track(seq.frames, seq.roi, cut_attached=False)["ok"].iloc[1:].any()
    # (min_track_score=None: its frames also match the template too poorly to vouch for, which flags them too.)
    free = frame_errors(track(seq.frames, seq.roi, min_resolved_contrast=None, min_track_score=None,
                              cut_attached=False), seq.truth, seq.roi)
    ok = free[free["ok"] & (free["frame"] > 0)]
    assert (np.hypot(ok["ex"], ok["ey"]) > 1.0).sum() >= 3


def test_a_jump_is_ambiguous_only_far_from_the_prediction_at_a_poor_match():
    far, near = AMBIGUOUS_JUMP_PX + 0.1, AMBIGUOUS_JUMP_PX
    assert ambiguous_jump(far, 0.7, 0.8)
    assert not ambiguous_jump(near, 0.7, 0.8)  # within a change of speed's reach
    assert not ambiguous_jump(far, 0.8, 0.8)  # the match vouches for it
    # No typical score yet (frame 1 from the coarse search): beyond a steady pixel, nothing vouches for it.
    assert ambiguous_jump(UNVOUCHED_JUMP_PX + 0.1, 0.99, None)
    assert not ambiguous_jump(UNVOUCHED_JUMP_PX, 0.1, None)
    assert ambiguous_jump(0.6, 0.99, None, limit_px=0.5)  # a stricter max_poor_jump stays stricter
    assert ambiguous_jump(far, float("nan"), 0.8)
    assert ambiguous_jump(2.0, 0.7, 0.8, limit_px=1.0)


def test_a_far_jump_before_the_track_has_a_typical_score_is_flagged():
    # thin_low_dose 103 (dev): frame 1's fit from frame 0 fails and the coarse search finds the shaft
    # ~7 px along its axis from the tip, at a score (0.93) no registered frame can vouch for yet. It used
    # to pass as ok: the jump check had no typical score to judge it by.
    seq = make_family_sequence("thin_low_dose", 103)
    t = Tracker()
    t.init(seq.frames[0], seq.roi)
    r = t.update(seq.frames[1])
    assert r.reason.startswith("ambiguous: the coarse search's answer") and "no typical score" in r.reason
    assert not r.ok
    # Without the check it was the silent error the flag now reports (more than 2 px off).
    loose = track(seq.frames[:2], seq.roi, max_poor_jump=None)
    errors = frame_errors(loose, seq.truth[seq.truth["frame"] <= 1], seq.roi)
    assert loose["ok"].iloc[1] and np.hypot(errors["ex"].iloc[1], errors["ey"].iloc[1]) > 2.0


def test_a_slide_along_a_shaft_the_registration_drifts_from_is_flagged(monkeypatch):
    # clutter 106 (dev) with the particle at its apex kept (the frames' cut of semlab.tracking.pieces, which
    # takes it at frame 28, switched off): at frame 39 a particle crosses the shaft, the fit fails and the
    # re-acquisition's correlation slides ~6 px along the shaft at a score (0.96) above the track's typical one.
    # The registration from there matches (0.88) but does not converge: the cost has no clear minimum.
    monkeypatch.setattr(ic, "loose_pieces", lambda region: [])
    seq = make_family_sequence("clutter", 106)
    t = Tracker()
    t.init(seq.frames[0], seq.roi)
    results = [t.update(frame) for frame in seq.frames[1:40]]
    assert not results[-1].ok and "drifts away" in results[-1].reason
    # Without the jump check it was a silent error (more than 2 px off, ok=True).
    loose = track(seq.frames[:40], seq.roi, max_poor_jump=None)
    errors = frame_errors(loose, seq.truth[seq.truth["frame"] < 40], seq.roi)
    assert loose["ok"].iloc[39] and np.hypot(errors["ex"].iloc[39], errors["ey"].iloc[39]) > 2.0


class _Track:
    """What the Judge asks of a method: whether it judges, whether its background is textured, its track score."""

    flags_uncertain = True

    def __init__(self, flatten: bool, track_score):
        self.flatten, self._track_score = flatten, track_score

    def track_score(self):
        return self._track_score


def test_a_falling_match_is_judged_slid_over_a_textured_substrate_only():
    drop = MAX_TEXTURED_SCORE_DROP
    assert slid_on_texture(0.9 - drop - 0.01, 0.9)
    assert not slid_on_texture(0.9 - drop + 0.01, 0.9)
    assert not slid_on_texture(0.1, None)  # no track score yet
    judge = Judge(LossOptions(), 30.0, _Track(flatten=True, track_score=0.9))
    assert judge.doubt_match(0.8).startswith("slid: over a strongly textured substrate the match scores 0.80")
    assert judge.doubt_match(0.87) is None
    # A flat background's falling match is an occluder or a change of charge: not judged by it.
    assert Judge(LossOptions(), 30.0, _Track(flatten=False, track_score=0.9)).doubt_match(0.5) is None
    assert Judge(LossOptions(max_textured_drop=None), 30.0, _Track(True, 0.9)).doubt_match(0.5) is None
    with pytest.raises(ValueError, match="max_textured_drop"):
        LossOptions(max_textured_drop=1.5)


@pytest.mark.slow
def test_a_track_sliding_onto_a_textured_substrate_is_flagged_and_followed():
    # Spare seed 247 of the substrates family (not a test seed): grains as bright as the probe lie along
    # its flank, and the registration slides along the shaft onto them, up to 6.6 px off while its
    # precision says a few tenths: all 48 frames after frame 1 are ok and more than 1 px off without the
    # check. With it the frames whose match fell are flagged "slid", at least half of them, and the
    # tracker follows every frame exactly as without it.
    seq = make_family_sequence("substrates", 247)
    t = Tracker()
    t.init(seq.frames[0], seq.roi)
    assert t.algorithm.flatten
    followed = track(seq.frames, seq.roi, max_textured_drop=None)
    free = frame_errors(followed, seq.truth, seq.roi)
    silent = free["ok"] & (np.hypot(free["ex"], free["ey"]) > 1.0)
    assert silent.sum() >= 40
    judged = [t.update(frame) for frame in seq.frames[1:]]
    flagged = [k for k, r in enumerate(judged, 1) if not r.ok]
    slid = [k for k in flagged if judged[k - 1].reason.startswith("slid")]
    assert len(slid) >= len(flagged) - 1  # (one frame of the grains' pull is "inconsistent")
    assert len(slid) >= silent.sum() / 2 and silent[slid].all()
    kept = [k for k in range(1, len(seq.frames)) if k not in flagged]
    assert [(judged[k - 1].x, judged[k - 1].y) for k in kept] == list(zip(followed["x"][kept], followed["y"][kept]))


def _results(frames, roi, **options):
    tracker = Tracker(**options)
    tracker.init(frames[0], roi)
    return [tracker.update(frame) for frame in frames[1:]]


def test_a_jump_to_a_poor_match_is_flagged_and_followed(monkeypatch):
    # A wedge drifting 0.3 px a frame, then jumping 12 px: with a typical score no match reaches, the
    # jump's frame is flagged "ambiguous" (the steady frames stay within a pixel of their prediction, the
    # frames after the jump within one of the jump's position), the next DOUBT_FRAMES frames, 12 px from
    # where the track was last trusted, "in doubt", the one after trusted again; and the tracker follows
    # them exactly as without the check. With the track's own typical score the jump's match vouches for it.
    frames = [wedge_frame(0.3 * k, 0.1 * k, noise=4.0, seed=k) for k in range(8)]
    frames += [wedge_frame(12.0 + 0.3 * k, 6.0, noise=4.0, seed=50 + k) for k in range(DOUBT_FRAMES + 2)]
    assert all(r.ok for r in _results(frames, ROI))
    monkeypatch.setattr(ICMethod, "typical_score", lambda self: 1.01)
    judged, free = _results(frames, ROI), _results(frames, ROI, max_poor_jump=None)
    assert all(r.ok for r in free)
    flagged = [k for k, r in enumerate(judged, 1) if not r.ok]
    assert flagged == list(range(8, 8 + DOUBT_FRAMES + 1))
    assert judged[7].reason.startswith("ambiguous") and math.isnan(judged[7].x)
    assert all(judged[k - 1].reason.startswith("in doubt") for k in flagged[1:])
    assert judged[-1].ok and (judged[-1].x, judged[-1].y) == (free[-1].x, free[-1].y)
    assert [(r.x, r.y) for r in judged[8 + DOUBT_FRAMES:]] == [(r.x, r.y) for r in free[8 + DOUBT_FRAMES:]]


@pytest.mark.slow
def test_a_whole_frame_match_along_the_shaft_under_an_occluder_is_flagged():
    # Spare seed 231 of the clutter family (not a test seed): an occluder hides the tip over frames
    # 22-31; in frame 28 the registration from the prediction fails, and the whole frame's best match
    # is the shaft 36 px along its axis, scoring 0.74 against the track's typical 0.82, reported ok
    # without the check. With it that frame is flagged, and so is the next, back on the hidden tip 35 px
    # away at 0.76 (after a jump no move is expected); the two after that, still more than 3 px from where
    # the track was last trusted, are "in doubt" (semlab.tracking.trust.JumpDoubt); every other frame is
    # as before.
    seq = make_family_sequence("clutter", 231)
    free = frame_errors(track(seq.frames, seq.roi, max_poor_jump=None), seq.truth, seq.roi)
    judged = _results(seq.frames, seq.roi)
    assert free.loc[28, "ok"] and np.hypot(free.loc[28, "ex"], free.loc[28, "ey"]) > 30
    assert all(not r.ok and r.reason.startswith("ambiguous") for r in judged[27:29])
    assert all(not r.ok and r.reason.startswith("in doubt") for r in judged[29:31])
    assert [r.ok for r in judged[:27] + judged[31:]] == list(free["ok"].iloc[1:].drop([28, 29, 30, 31]))


def test_a_young_template_inflates_the_reported_sigma_only(monkeypatch):
    assert young_template_inflation(1) == young_template_inflation(YOUNG_TEMPLATE_FRAMES - 1) == YOUNG_TEMPLATE_INFLATION
    assert young_template_inflation(YOUNG_TEMPLATE_FRAMES) == 1.0 and YOUNG_TEMPLATE_INFLATION > 1.0
    # The reported sigma grows with it on a still wedge's first three frames (templates of frame 0,
    # then frames 0-1), and not later. Frame 1: the origin is exact and the object has not moved, so
    # the fit's part is all of sigma; frames 2-3 add the origin's covariance, not inflated. The
    # precision the flags judge by does not change, nor does any answer.
    frames = [wedge_frame(0.0, 0.0, noise=4.0, seed=k) for k in range(8)]
    inflated = track(frames, ROI, template_frames=8)
    monkeypatch.setattr(uncertainty, "YOUNG_TEMPLATE_INFLATION", 1.0)
    plain = track(frames, ROI, template_frames=8)
    ratio = inflated["sigma_x"] / plain["sigma_x"]
    assert ratio.iloc[1] == pytest.approx(YOUNG_TEMPLATE_INFLATION, rel=0.01)
    assert all(1.05 < r < YOUNG_TEMPLATE_INFLATION for r in ratio.iloc[2:4])
    assert np.allclose(ratio.iloc[4:], 1.0)
    assert inflated[["x", "y", "ok"]].equals(plain[["x", "y", "ok"]])


def test_model_error_grows_with_the_displacement_from_frame_0():
    assert model_error(0.0) == 0.0 and model_error(0.5) == pytest.approx(0.5 * MODEL_ERROR_PX)
    assert model_error(40.0) == MODEL_ERROR_PX and model_error(float("nan")) == MODEL_ERROR_PX


def test_model_error_grows_with_the_change_of_appearance():
    # Gain change and misfit add in quadrature to the floor; a score above the typical one adds nothing.
    assert model_error(40.0, gain=1.3) == pytest.approx(math.hypot(MODEL_ERROR_PX, 0.3 * MODEL_ERROR_PER_GAIN_PX))
    assert model_error(40.0, gain=0.7) == model_error(40.0, gain=1.3)
    misfit = TYPICAL_MATCH_SCORE - 0.7
    assert model_error(40.0, score=0.7) == pytest.approx(math.hypot(MODEL_ERROR_PX, misfit * MODEL_ERROR_PER_MISFIT_PX))
    assert model_error(40.0, score=0.99) == MODEL_ERROR_PX
    assert model_error(0.5, gain=1.3, score=0.7) == pytest.approx(0.5 * model_error(40.0, gain=1.3, score=0.7))
    assert model_error(40.0, gain=float("nan"), score=float("nan")) == MODEL_ERROR_PX


def test_least_squares_covariance_is_s2_over_the_information():
    rng = np.random.default_rng(1)
    jac = rng.normal(size=(500, 2))
    residual = rng.normal(0.0, 3.0, 500)
    cov = least_squares_covariance(jac, residual)
    np.testing.assert_allclose(cov, residual @ residual / 498 * np.linalg.inv(jac.T @ jac))
    assert np.isinf(least_squares_covariance(jac[:2], residual[:2])).all()  # no degrees of freedom


# --------------------------------------------------------------------------- encodings
@pytest.mark.parametrize("method", METHODS)
def test_the_encoding_of_the_gray_levels_never_changes_the_answer(method):
    # The same 8-bit frames as uint8, uint16 (x257), float32 in 0-255 and float in 0-1
    # (skimage.img_as_float): the same track within 0.01 px, the same flags.
    from semlab.sim import make_sequence

    frames8 = make_sequence("moves_200px", seed=1, n_cycles=1).frames[:14]
    roi = make_sequence("moves_200px", seed=1, n_cycles=1).roi
    reference = track(frames8, roi, method=method)
    for frames in (frames8.astype(np.uint16) * 257, frames8.astype(np.float32), img_as_float(frames8)):
        other = track(frames, roi, method=method)
        assert (other["ok"] == reference["ok"]).all()
        ok = reference["ok"]
        np.testing.assert_allclose(other.loc[ok, ["x", "y"]], reference.loc[ok, ["x", "y"]], atol=0.01)


def test_float_frames_in_0_1_are_a_probe_not_noise():
    frame = wedge_frame(0.0, 0.0, noise=3.0) / 255.0
    r = Tracker().init(frame, ROI)
    assert r.ok


# --------------------------------------------------------------------------- the corpus
def _coverage(family, seed):
    seq = make_family_sequence(family, seed)
    df = track(seq.frames, seq.roi, progress=False)
    e = frame_errors(df, seq.truth, seq.roi)
    e = e[(e.frame > 0) & e.ok & e.visible]
    d2 = (e.ex / e.sigma_x) ** 2 + (e.ey / e.sigma_y) ** 2
    return float(np.mean(d2 <= 5.991)), len(e) / max(len(seq.frames) - 1, 1)


@pytest.mark.slow
@pytest.mark.parametrize("family", ["still", "moves_200px", "jumps", "shapes", "substrates"])
def test_sigma_is_calibrated_on_the_corpus(family):
    # Development seed 100 of the families where the model error is what MODEL_ERROR_PX says: 95 %
    # ellipses hold 80-100 % of the ok frames (a 40-60-frame sequence: ±6 % binomial error, and its
    # frames share one origin, so the coverage of one sequence scatters more than that).
    coverage, _ = _coverage(family, 100)
    assert 0.8 <= coverage <= 1.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known limitation (issue 14, measured on development seed 107): under probe-only charging with strong "
    "gain jitter and in dense drifting clutter the sequence's bias exceeds the model error the tracker adds "
    "(MODEL_ERROR_PX plus the gain-change and misfit terms): 95 % ellipses hold 71 % (gray_charging) and 59 % "
    "(clutter) of the frames; wander 98 %"))
def test_sigma_is_calibrated_where_the_background_pulls():
    assert all(_coverage(f, 107)[0] >= 0.8 for f in ("wander", "gray_charging", "clutter"))


def test_low_dose_starts():
    # A few electrons per pixel: the contour's contrast is under twice one pixel's noise but many
    # times that of the smoothed ROI the contour is found in: the tracker starts (issue 14; it
    # refused 10 of 10 test seeds before).
    seq = make_family_sequence("low_dose", 100)
    assert Tracker().init(seq.frames[0], seq.roi).ok


def test_semlab_track_reports_the_sigma_too():
    frames = [wedge_frame(0.3 * k, 0.0, noise=3.0, seed=k) for k in range(4)]
    df = semlab.track(frames, ROI)
    assert {"sigma_x", "sigma_y"} <= set(df.columns) and (df["sigma_x"].iloc[1:] > 0).all()
