"""Loop closures (graphnav.graph.loops): a synthetic loop with known truth, a corridor whose
look-alike place must be refused, and a wrong loop that the robust kernel and the pairwise
consistency check must neutralise."""

from __future__ import annotations

import math

import _scan_sim as S
import gtsam
import numpy as np
import pytest

import factors as F
from graphnav.graph import loops as LP
from graphnav.graph.builder import Step, make_loop_closer
from graphnav.graph.navigator import Navigator
from graphnav.graph.smoother_config import SmootherConfig
from graphnav.log import NavLog, Odometry, Scan, Truth


def _box(x0, y0, x1, y1):
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def _hall() -> np.ndarray:
    """A 40 x 30 m hall with irregular boxes off a circle of radius 9 m about the origin."""
    segs = [*_box(-20, -15, 20, 15), *_box(-16, 11, -12, 13), *_box(13, 10, 15, 13), *_box(12, -13, 17, -11),
            *_box(-15, -12, -13, -7), *_box(-2, -2, 1, 1), (-18, 2, -15, 5), (4, -15, 6, -12), (8, 15, 10, 12)]
    return np.array(segs, dtype=float)


def _loop_log(seed: int = 0, laps: float = 1.6, sigma_w: float = 0.015) -> tuple[NavLog, np.ndarray]:
    """Scans (180 beams over 180 deg, 1 s apart), truth and odometry (white noise, its sigmas stated:
    3 cm/s, ``sigma_w`` rad/s) on a circle of radius 9 m at 1 m/s, counter-clockwise: the track comes
    back to its start after one lap."""
    rng = np.random.default_rng(seed)
    segs = _hall()
    r0, v = 9.0, 1.0
    w = v / r0
    n = int(laps * 2 * math.pi / w)
    ang = -math.pi / 2 + np.arange(180) * math.pi / 180
    recs = []
    poses = []
    for k in range(n + 1):
        t = float(k)
        a = -math.pi / 2 + w * t
        pose = np.array([r0 * math.cos(a), r0 * math.sin(a), a + math.pi / 2])
        poses.append(pose)
        rr = S.raycast(segs, pose, ang) + rng.normal(0, 0.01, 180)
        recs.append(Scan(t, rr, ang.copy()))
        recs.append(Truth(t, *map(float, pose)))
        recs.append(Odometry(t, v + rng.normal(0, 0.03), w + rng.normal(0, sigma_w), 0.03, sigma_w))
    return NavLog.from_unsorted(recs, meta={"name": "loop"}), np.array(poses)


def _run(log: NavLog, **options):
    nav = Navigator.for_log(log, **options)
    for rec in log:
        nav.add(rec)
    return nav.result()


def _ate(res, truth: np.ndarray) -> float:
    p = res.trajectory.poses
    return float(np.sqrt(np.mean(np.sum((p[:, :2] - truth[:, :2]) ** 2, axis=1))))


def test_batch_solves_the_graph_isam2_closes():
    # one front end: batch's loop decisions come from the same iSAM2 estimates as the isam2 run's,
    # so both solve the same graph and reach the same optimum (each solved to the end: lm_abs_tol 0)
    log, truth = _loop_log(seed=1)
    on = _run(log, use_icp=False, lm_abs_tol=0.0, lm_stall_tol=0.0)
    ba = _run(log, use_icp=False, solver="batch", lm_abs_tol=0.0, lm_stall_tol=0.0)
    assert ba.info["loop_edges"] == on.info["loop_edges"] and len(on.info["loop_edges"]) >= 5
    np.testing.assert_allclose(ba.trajectory.poses, on.trajectory.poses, atol=1e-4)


def test_synthetic_loop_is_closed_with_bounded_error():
    log, truth = _loop_log(seed=1)
    on = _run(log, use_icp=False)  # odometry only: the drift is the loops' to remove
    off = _run(log, use_icp=False, loops=False)
    assert on.info["loop_closures"] >= 5
    assert on.info["loop_candidates"] >= on.info["loop_closures"]
    for i, k in on.info["loop_edges"]:  # every accepted loop is right
        z = gtsam.Pose2(*truth[i]).between(gtsam.Pose2(*truth[k]))
        e = gtsam.Pose2(*on.trajectory.poses[i]).between(gtsam.Pose2(*on.trajectory.poses[k]))
        assert math.hypot(z.x() - e.x(), z.y() - e.y()) < 0.3
    t = on.trajectory.t  # the edges' times (what the report's plot marks) are those keyframes' times
    assert on.info["loop_edge_times"] == [[t[i], t[k]] for i, k in on.info["loop_edges"]]
    a_on, a_off = _ate(on, truth), _ate(off, truth)
    assert a_off > 0.8  # the drift is real
    assert a_on < 0.35 * a_off and a_on < 0.6
    # the online estimate takes the loops too: its last poses are close to the truth
    last = on.online.poses[-1]
    assert math.hypot(*(last[:2] - truth[-1, :2])) < 0.5 * math.hypot(*(off.online.poses[-1][:2] - truth[-1, :2]))


def test_loops_off_and_batch_and_fixed_lag():
    log, truth = _loop_log(seed=1, laps=1.3)
    assert "loop_closures" not in _run(log, use_icp=False, loops=False).info
    b = _run(log, use_icp=False, solver="batch")
    assert b.info["loop_closures"] >= 1
    fl = _run(log, use_icp=False, solver="fixed-lag", lag=20.0)  # the loop lies outside the window: none
    assert fl.info["loop_closures"] == 0


def _corridor_with_doors(period: float = 6.0, length: float = 120.0) -> np.ndarray:
    """A corridor 4 m wide with identical door recesses every ``period`` metres on both walls."""
    segs = []
    x = -length / 2
    while x < length / 2:
        for side in (-1, 1):
            y = 2.0 * side
            segs += [(x, y, x + period - 1.0, y), (x + period - 1.0, y, x + period - 1.0, y + side),
                     (x + period - 1.0, y + side, x + period, y + side), (x + period, y + side, x + period, y)]
        x += period
    return np.array(segs, dtype=float)


def _closer(**loop):
    cfg = SmootherConfig(loop=loop)
    return make_loop_closer(cfg.scan, {}), cfg


def _step():
    return Step(0, 0.0, gtsam.NonlinearFactorGraph(), gtsam.Values(), {})


def test_repeated_corridor_look_alike_is_refused():
    """First pass east along the corridor; the second pass east again with an estimate one door
    period (5 m) ahead of the truth, which the odometry's along-track sigma (0.35 m per 1 m step:
    2.7 m over the 60 steps between the passes) allows: the look-alike place at the estimate matches
    perfectly, the true one as well -- the match is ambiguous and must be refused. (Past the end of
    the first pass the look-alike has no twin in the submap: a loop found there must be the true one.)"""
    segs = _corridor_with_doors(period=5.0)
    rng = np.random.default_rng(0)
    ang = -math.pi / 2 + np.arange(180) * math.pi / 180
    closer, _ = _closer()
    cov = np.diag([3.0**2, 3.0**2, math.radians(2.0) ** 2])
    q = np.diag([0.35**2, 0.05**2, 1e-6])
    k = 0
    s = _step()
    truths = []
    for sweep, offset in ((0, 0.0), (1, 5.0)):
        for x in np.arange(-40.0, 20.0, 1.0):
            truth = np.array([x + 0.13 * sweep, 0.2 * sweep, 0.0])
            est = truth + [offset, 0.0, 0.0]
            truths.append(truth)
            xy = S.points(S.raycast(segs, truth, ang) + rng.normal(0, 0.01, 180), ang)
            rel = gtsam.Pose2(1.0, 0.0, 0.0) if k else None
            closer.step(s, k, gtsam.Pose2(*est), cov, rel, q if k else None, xy)
            k += 1
    assert closer.counts["loop_candidates"] > 50
    assert closer.counts["loop_rejected_match"] > 50  # the look-alikes: ambiguous
    assert closer.counts["loop_closures"] == s.graph.size() <= 8
    for n in range(s.graph.size()):  # whatever was accepted is the truth, not the look-alike
        f = s.graph.at(n)
        i, k = (gtsam.Symbol(key).index() for key in f.keys())
        z = gtsam.Pose2(*truths[i]).between(gtsam.Pose2(*truths[k]))
        assert abs(f.measured().x() - z.x()) < 0.3


def test_featureless_corridor_is_refused():
    segs = S.corridor(200.0, 2.0)
    ang = -math.pi / 2 + np.arange(180) * math.pi / 180
    closer, _ = _closer(min_hits=0.3)
    s = _step()
    k = 0
    cov = np.diag([0.3**2, 0.3**2, math.radians(1.0) ** 2])
    for sweep in range(2):
        for x in np.arange(-30.0, 10.0, 1.0):
            truth = np.array([x + 0.4 * sweep, 0.1 * sweep, 0.0])
            xy = S.points(S.raycast(segs, truth, ang), ang)
            closer.step(s, k, gtsam.Pose2(*truth), cov, gtsam.Pose2(1.0, 0.0, 0.0) if k else None,
                        np.diag([0.01, 0.01, 1e-4]) if k else None, xy)
            k += 1
    assert closer.counts["loop_candidates"] > 10
    assert closer.counts["loop_closures"] == 0  # along a bare corridor no match is informative


def _square(wrong_kernel: str | None):
    """A square track of 48 poses (odometry with a yaw drift), closed by 4 correct loops (the map as
    the online estimate has it once they are in); then, if ``wrong_kernel`` is given, a loop 8 m off
    added by the closer with that kernel and the graph re-solved from the closed map. Returns the
    position RMSE against the truth."""
    truth = []
    for k in range(48):
        side, u = divmod(k, 10)
        c = [(0, 0), (10, 0), (10, 10), (0, 10)][side % 4]
        d = [(1, 0), (0, 1), (-1, 0), (0, -1)][side % 4]
        truth.append(np.array([c[0] + d[0] * u, c[1] + d[1] * u, math.atan2(d[1], d[0])]))
    g = gtsam.NonlinearFactorGraph()
    v = gtsam.Values()
    g.add(gtsam.PriorFactorPose2(F.X(0), gtsam.Pose2(*truth[0]), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)))
    rng = np.random.default_rng(0)
    odo = gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.05, math.radians(1.0)])
    est = gtsam.Pose2(*truth[0])
    v.insert(F.X(0), est)
    for k in range(1, len(truth)):
        z = gtsam.Pose2(*truth[k - 1]).between(gtsam.Pose2(*truth[k]))
        z = z.compose(gtsam.Pose2(rng.normal(0, 0.02), rng.normal(0, 0.02), math.radians(0.5)))  # yaw drift
        g.add(gtsam.BetweenFactorPose2(F.X(k - 1), F.X(k), z, odo))
        est = est.compose(z)
        v.insert(F.X(k), est)
    cov = np.diag([0.05**2, 0.05**2, math.radians(0.5) ** 2])

    def loop(i: int, k: int, off: float = 0.0) -> LP.Loop:
        z = gtsam.Pose2(*truth[i]).between(gtsam.Pose2(*truth[k])).compose(gtsam.Pose2(off, 0.0, 0.0))
        return LP.Loop(i, k, 0.0, 0.0, np.array([z.x(), z.y(), z.theta()]), cov, "test")

    closer, _ = _closer(kernel="cauchy")
    s = _step()
    for i, k in [(0, 40), (1, 41), (2, 42), (3, 43)]:
        closer._add_factor(s, loop(i, k))
    g.push_back(s.graph)
    v = gtsam.LevenbergMarquardtOptimizer(g, v).optimize()
    if wrong_kernel is not None:
        closer, _ = _closer(kernel=wrong_kernel)
        s = _step()
        closer._add_factor(s, loop(5, 46, 8.0))
        g.push_back(s.graph)
        v = gtsam.LevenbergMarquardtOptimizer(g, v).optimize()
    p = np.array([[v.atPose2(F.X(k)).x(), v.atPose2(F.X(k)).y()] for k in range(len(truth))])
    return float(np.sqrt(np.mean(np.sum((p - np.array(truth)[:, :2]) ** 2, axis=1))))


def test_injected_wrong_loop_is_neutralised_by_the_kernel():
    right = _square(None)
    assert right < 0.2  # the correct loops close the square
    assert _square("cauchy") < right + 0.05  # the wrong loop barely moves the robust solution
    assert _square("dcs") < right + 0.05
    assert _square("none") > right + 1.0  # without a kernel it bends the map


def test_pairwise_consistency_refuses_a_wrong_loop():
    closer, _ = _closer()
    q = np.diag([0.02**2, 0.02**2, math.radians(0.3) ** 2])
    for k in range(30):  # a straight chain, 1 m steps
        closer.chain.steps.append((gtsam.Pose2(1.0, 0.0, 0.0) if k else gtsam.Pose2(), q if k else np.zeros((3, 3))))
    cov = np.diag([0.05**2, 0.05**2, math.radians(0.5) ** 2])
    # keyframe 20 is beside keyframe 2 (one metre to the left), 22 beside 4: a straight revisit
    l1 = LP.Loop(2, 20, 2.0, 20.0, np.array([0.0, 1.0, 0.0]), cov, "gate")
    l2 = LP.Loop(4, 22, 4.0, 22.0, np.array([0.0, 1.0, 0.0]), cov, "gate")
    bad = LP.Loop(4, 22, 4.0, 22.0, np.array([3.0, 1.0, 0.0]), cov, "gate")  # a look-alike 3 m on
    # the chains 20 -> 22 and 4 -> 2 are both 2 m: the cycle closes for l2 and not for bad
    closer.chain.steps[20:23] = [(gtsam.Pose2(1.0, 0.0, 0.0), q)] * 3
    assert closer.consistent(l1, l2)
    assert not closer.consistent(l1, bad)


def test_compound_and_propagate_against_closed_form():
    q = np.diag([0.1**2, 0.2**2, 0.05**2])
    T, C = LP.compound([(gtsam.Pose2(1.0, 0.0, 0.0), q), (gtsam.Pose2(1.0, 0.0, 0.0), q)])
    assert T.x() == pytest.approx(2.0)
    # two straight steps: x var adds, y var = 2 * 0.04 + (1 m * yaw sigma of the first step)^2
    assert C[0, 0] == pytest.approx(0.02)
    assert C[1, 1] == pytest.approx(0.08 + 0.05**2)
    assert C[2, 2] == pytest.approx(2 * 0.05**2)
    w = LP.propagate(np.zeros((3, 3)), np.array([0.0, 0.0, math.pi / 2]), gtsam.Pose2(1.0, 0.0, 0.0), q)
    assert w[0, 0] == pytest.approx(0.04) and w[1, 1] == pytest.approx(0.01)  # body axes turned by 90 deg


def test_unknown_loop_option_is_named():
    with pytest.raises(ValueError, match="unknown loop option.*bogus"):
        Navigator(scans=True, loop={"bogus": 1})


def test_motion_chain_covariance_from_prefixes_equals_the_direct_compounding():
    """Beyond DIRECT_STEPS the chain's relative covariance comes from the prefixes P_b - M P_a M^T: the
    same as compounding step by step (to 1e-8 relative, 3000 random steps), and positive definite."""
    import gtsam

    from graphnav.graph.loop_places import DIRECT_STEPS, MotionChain

    rng = np.random.default_rng(0)
    ch = MotionChain()
    ch.add(None, None)
    for _ in range(3000):
        rel = gtsam.Pose2(0.5 + rng.normal(0, 0.1), rng.normal(0, 0.05), rng.normal(0, 0.05))
        ch.add(rel, np.diag([1e-4, 4e-4, 1e-6]) * rng.uniform(0.5, 2.0))
    for a, b in ((10, 10 + DIRECT_STEPS + 1), (2000, 2100), (100, 2900), (2800, 2990)):
        C = np.zeros((3, 3))
        for k in range(a + 1, b + 1):
            C = ch.adj[k] @ C @ ch.adj[k].T + ch.steps[k][1]
        got = ch.covariance(a, b)
        assert np.max(np.abs(got - C)) < 1e-8 * np.max(np.abs(C))
        assert np.linalg.eigvalsh(got).min() > 0


def test_place_index_finds_the_nearest_valid_rows_as_a_linear_scan_does():
    """The places' index (a k-d tree over most rows, a linear scan over the newest): the ``n`` nearest among
    the first ``valid`` rows, as distances and indices, nearest first."""
    from graphnav.graph.loop_places import _Index

    rng = np.random.default_rng(3)
    rows = rng.uniform(-50.0, 50.0, size=(300, 2))
    idx = _Index()
    for i, r in enumerate(rows):
        idx.add(r)
        if i % 37 == 36:
            q = rng.uniform(-50.0, 50.0, size=2)
            for n, valid in ((5, i + 1), (8, max(1, i // 2)), (400, i - 3)):
                d = np.hypot(*(rows[:valid] - q).T)
                want = sorted(zip(d.tolist(), range(valid), strict=True))[:n]
                got = idx.nearest(q, n, valid)
                assert [j for _, j in got] == [j for _, j in want]
                np.testing.assert_allclose([x for x, _ in got], [x for x, _ in want], rtol=1e-12)


class _ListIndex:
    """The places' index as it was (rows in a list, the tail turned into an array per query): the reference."""

    def __init__(self) -> None:
        from scipy.spatial import cKDTree

        self.kd, self.rows, self.tree, self.n_tree = cKDTree, [], None, 0

    def add(self, v: np.ndarray) -> None:
        self.rows.append(np.asarray(v, dtype=float))
        if len(self.rows) - self.n_tree > max(32, len(self.rows) // 4):
            self.rebuild()

    def rebuild(self) -> None:
        self.n_tree = len(self.rows)
        self.tree = self.kd(np.array(self.rows)) if self.rows else None

    def nearest(self, q: np.ndarray, n: int, valid: int) -> list[tuple[float, int]]:
        out: list[tuple[float, int]] = []
        if self.tree is not None and self.n_tree:
            d, idx = self.tree.query(q, k=min(n + max(0, self.n_tree - valid), self.n_tree))
            d, idx = np.atleast_1d(d), np.atleast_1d(idx)
            ok = np.isfinite(d) & (idx < valid)
            out.extend(zip(d[ok].tolist(), idx[ok].tolist(), strict=True))
        lo, hi = self.n_tree, min(len(self.rows), valid)
        if hi > lo:
            d = np.linalg.norm(np.array(self.rows[lo:hi]) - q, axis=1)
            out.extend((float(dd), lo + j) for j, dd in enumerate(d))
        out.sort()
        return out[:n]


def test_place_index_answers_as_the_list_index_did_with_ties_and_moved_rows():
    """The array-backed index answers exactly as the list-backed one did: rows on a coarse grid (many equal
    distances), some moved after they were indexed (the tree keeps where it saw them until a rebuild)."""
    from graphnav.graph.loop_places import _Index

    rng = np.random.default_rng(5)
    new, old = _Index(), _ListIndex()
    for i in range(400):
        v = rng.integers(0, 6, size=2).astype(float)
        new.add(v)
        old.add(v)
        if i % 3 == 0:  # the newest row moves (a place's solved pose replacing its prediction)
            w = v + rng.integers(-1, 2, size=2)
            new.set(i, w)
            old.rows[i] = w
        if i % 11 == 10:
            q = rng.integers(0, 6, size=2).astype(float)
            for n, valid in ((1, i + 1), (5, i + 1), (8, max(1, i // 2)), (60, i - 3), (3, max(1, i - 40))):
                assert new.nearest(q, n, valid) == old.nearest(q, n, valid)
    assert 0 < new.n_tree < 400 and new.n_tree == old.n_tree


def test_a_refresh_reads_the_settled_places_once():
    """``Places.refresh``: places whose estimate became final (an earlier iSAM2 segment's) are read once more,
    then no longer; ``None`` leaves a place where it was; the position index answers the refreshed places."""
    from graphnav.graph.loop_places import Deferred, Place, Places
    from graphnav.scan import correlative as corr

    places = Places(corr.CorrelativeConfig(), 5, 5)
    for k in range(10):
        places.add(Place(k, float(k), np.array([float(k), 0.0, 0.0]), np.eye(3), np.zeros((0, 2)), None))
    asked: list[list[int]] = []

    def estimate(ks: list[int]) -> list[np.ndarray | None]:
        asked.append(list(ks))
        return [np.array([float(k), 1.0 + len(asked), 0.0]) if k % 3 else None for k in ks]

    places.refresh(estimate, lambda k: k < 4)
    places.refresh(estimate, lambda k: k < 6)
    assert asked == [list(range(10)), list(range(4, 10))] and places.settled == 6
    assert [p.pose[1] for p in places.all] == [0.0, 2.0, 2.0, 0.0, 3.0, 3.0, 0.0, 3.0, 3.0, 0.0]
    assert places.near(np.array([4.0, 3.0]), 2, 10) == [(0.0, 4), (1.0, 5)]
    assert places.near(np.array([3.0, 0.0]), 1, 10) == [(0.0, 3)]
    # a deferred yaw: read when the place is first looked at, once; a newer estimate replaces it
    reads: list[int] = []

    def deferred(ks: list[int]) -> list[Deferred]:
        return [Deferred(np.array([float(k), 5.0]), lambda k=k: reads.append(k) or np.array([float(k), 5.0, 0.5]))
                for k in ks]

    places.refresh(deferred)
    assert places.near(np.array([7.0, 5.0]), 1, 10) == [(0.0, 7)] and reads == []
    assert places[7].pose.tolist() == [7.0, 5.0, 0.5] and places[7].pose.tolist() == [7.0, 5.0, 0.5]
    places.observe(8, np.array([8.0, 6.0, 0.25]), None)
    places.submap_of(6)
    assert reads == [7, 6, 9] and places[8].pose.tolist() == [8.0, 6.0, 0.25] and not places.deferred


def test_place_index_answers_as_the_list_index_did_on_ring_keys():
    """20-dimensional rows (the ring keys' index): the same distances to the bit as ``np.linalg.norm``'s."""
    from graphnav.graph.loop_places import _Index

    rng = np.random.default_rng(8)
    new, old = _Index(), _ListIndex()
    for i in range(300):
        v = rng.random(20) * 0.1
        new.add(v)
        old.add(v)
        if i % 7 == 6:
            q = rng.random(20) * 0.1
            for n, valid in ((1, i + 1), (10, i + 1), (10, max(1, i - 30))):
                assert new.nearest(q, n, valid) == old.nearest(q, n, valid)
