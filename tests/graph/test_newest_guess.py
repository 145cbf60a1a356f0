"""Batch's guess of a new keyframe: its own factors solved with the earlier variables held
(graphnav.graph.newest_guess)."""

from __future__ import annotations

import gtsam
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from graphnav.graph.newest_guess import solve_newest

X = gtsam.symbol_shorthand.X
L = gtsam.symbol_shorthand.L


def _pose2(key: int) -> str:
    return "Pose2"


coord = st.floats(-50.0, 50.0)


@settings(max_examples=40, deadline=None)
@given(coord, coord, st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(0.5, 5.0),
       st.floats(0.5, 5.0))
def test_a_motion_and_a_fix_meet_at_their_weighted_mean(x0, y0, th0, dx, dy, s_motion, s_fix):
    """Known answer: X0 held at (x0, y0, th0); X1's motion from it says (1, 0, 0), a prior on X1 (a fix with a
    compass's heading, 1 mrad) says (fx, fy, th0), a few sigma from the motion. Both measure X1 directly, so
    its position is their inverse-variance mean, whatever the guess (here 30 m and 0.5 rad off)."""
    p0 = gtsam.Pose2(x0, y0, th0)
    pred = p0.compose(gtsam.Pose2(1.0, 0.0, 0.0))
    fx, fy = pred.x() + dx, pred.y() + dy
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(1.0, 0.0, 0.0),
                                       gtsam.noiseModel.Diagonal.Sigmas(np.array([s_motion, s_motion, 0.1]))))
    g.add(gtsam.PriorFactorPose2(X(1), gtsam.Pose2(fx, fy, th0),
                                     gtsam.noiseModel.Diagonal.Sigmas(np.array([s_fix, s_fix, 1e-3]))))
    earlier = gtsam.Values()
    earlier.insert(X(0), p0)
    new = gtsam.Values()
    new.insert(X(1), gtsam.Pose2(pred.x() + 30.0, pred.y() - 20.0, th0 + 0.5))
    out = solve_newest(g, new, earlier, _pose2)
    w1, w2 = 1 / s_motion**2, 1 / s_fix**2
    want = (w1 * np.array([pred.x(), pred.y()]) + w2 * np.array([fx, fy])) / (w1 + w2)
    got = out.atPose2(X(1))
    assert np.allclose([got.x(), got.y()], want, atol=1e-4)
    # the heading: within its 1 mrad of th0 (Pose2's chart couples it to a large translation residual), and the
    # solution no worse than the closed form by the graph's own cost
    assert abs(np.angle(np.exp(1j * (got.theta() - th0)))) < 1e-3
    at = gtsam.Values(earlier)
    at.insert(out)
    closed = gtsam.Values(earlier)
    closed.insert(X(1), gtsam.Pose2(*want, th0))
    assert g.error(at) <= g.error(closed) * (1 + 1e-9) + 1e-9
    assert earlier.atPose2(X(0)).equals(p0, 1e-12)  # the earlier values are not touched
    assert out.size() == 1


def test_what_no_factor_sees_stays_at_the_guess_and_unknown_keys_are_left_out():
    """A fix alone (position only) moves the position and leaves the heading as guessed; a factor on a key that
    is neither new nor earlier (here a beacon) is left out instead of failing."""
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.GPSFactor(X(1), gtsam.Point3(10.0, -4.0, 0.0), gtsam.noiseModel.Isotropic.Sigma(3, 2.0)))
    g.add(gtsam.PriorFactorPoint3(L(7), gtsam.Point3(0.0, 0.0, 0.0), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    new = gtsam.Values()
    guess = gtsam.Pose3(gtsam.Rot3.Ypr(0.7, 0.1, -0.05), gtsam.Point3(0.0, 0.0, 0.0))
    new.insert(X(1), guess)
    out = solve_newest(g, new, gtsam.Values(), lambda key: "Pose3")
    got = out.atPose3(X(1))
    assert np.allclose(got.translation(), [10.0, -4.0, 0.0], atol=1e-5)
    assert got.rotation().equals(guess.rotation(), 1e-6)
