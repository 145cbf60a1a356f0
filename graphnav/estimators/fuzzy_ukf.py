"""The fuzzy adaptive UKF of Liu, Liu & Bucknall (IEEE Access 2019), section IV.

The UKF of :mod:`graphnav.estimators.ukf`, with the measurement noise covariance R adapted at every
update, per measurement channel j (GNSS x, GNSS y, compass):

* innovation ``eps = z - H x^-`` (eq. 14), theoretical covariance ``C_T = H P^- H^T + R`` (eq. 15),
* actual covariance ``C_A`` = mean of ``eps eps^T`` over the last N innovations (eq. 17), kept
  recursively (eq. 18: add the newest, drop the one that leaves the window),
* with ``c_a="centered"`` (default, not in the paper) C_A is the window's sample covariance of eps
  about its window mean (``n - 1`` normalisation) instead of eq. 17's second moment. Eq. 7-8 model
  the GNSS / compass noise as zero-mean white noise, so a persistent innovation mean is state /
  model error (e.g. the drift of a residual IMU bias), not sensor noise. Eq. 17 books it into C_A,
  eq. 21 raises R, the filter follows the measurements less, the drift and the innovation mean grow:
  a positive feedback that took the GNSS R_hat to ~19x the true noise and the position error to
  ~400 m (Solent scenario 2, seed 3). ``c_a="raw"`` is eq. 17 as printed,
* the systematic part goes to the state covariance instead (not in the paper; option ``mean_test``,
  a confidence level, default 0.95 for ``fuzzy-ukf``, off (``null``) for ``fuzzy-ukf-bias``, whose
  bias states estimate that model error): when the window mean ``mu`` of a channel's innovations is
  significant for a consistent filter (``mu^2 > chi2_1(mean_test) C_T / N``), the predicted
  covariance is inflated so that ``H P^- H^T >= mu^2`` (:meth:`FuzzyCovarianceMatcher.inflation`,
  :func:`graphnav.estimators.ukf.inflate`: a fading-memory factor on the position/velocity block for
  GNSS, on the heading for the compass). Eq. 15's ``C_T = H P^- H^T + R`` then matches both parts
  of the raw eq. 17 moment: R the zero-mean noise, ``H P^- H^T`` the state error,
* ``DoM_j = C_A,jj / C_T,jj`` (eq. 20), ``alpha_j`` from the fuzzy system of Table 1 / eq. 22-28
  (:mod:`graphnav.estimators.fuzzy`, thresholds of Table 2),
* ``R_hat = alpha R`` (eq. 21). With ``r_update="compound"`` (default) R(k) in eq. 21 and eq. 15 is
  the previous step's R_hat, so R moves until C_T matches C_A (the reading under which R_hat can
  converge to the true R, as the paper's Figs. 13/17 show); ``r_update="scale_prior"`` uses the
  fixed prior R of Table 2 in both (R_hat can then grow by at most the largest centroid, ~3.7).

The adaptation starts once the window holds N innovations of a channel (before that R = R_0).
Options: ``window`` (N, default 30; the paper does not state it), ``r_update``, ``c_a``,
``mean_test``, ``bias`` (true: run the adaptation on the bias-augmented ``ukf-bias`` state, our
extension), and every option of ``ukf``.
``info`` holds per-step ``r_hat``, ``c_a``, ``c_t``, ``dom`` and ``alpha`` (arrays (n, 3)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import option
from ..graph.chi2 import chi2_ppf
from ..log import NavLog
from ..result import OnEstimate, RunResult
from .fuzzy import FuzzyAlpha, Thresholds
from .imu_model import resolve_flag, wants_bias
from .ukf import DEFAULTS, Ukf, UkfOptions, channel_variances, measurement_table, run_nav_filter


class FuzzyCovarianceMatcher:
    """Per-channel covariance matching with the fuzzy coefficient; call it as the UKF's adapter."""

    def __init__(self, r0: NDArray, n_steps: int, window: int = 30, r_update: str = "compound",
                 th: Thresholds | None = None, c_a: str = "centered", mean_test: float | None = 0.95) -> None:
        if r_update not in ("compound", "scale_prior"):
            raise ValueError(f"r_update must be 'compound' or 'scale_prior', not {r_update!r}")
        if c_a not in ("centered", "raw"):
            raise ValueError(f"c_a must be 'centered' or 'raw', not {c_a!r}")
        if window < 1 or (c_a == "centered" and window < 2):
            raise ValueError("window must be >= 1 (>= 2 with c_a='centered')")
        self.centered = c_a == "centered"
        if mean_test is not None and not 0.0 < mean_test < 1.0:
            raise ValueError(f"mean_test must be a confidence level in (0, 1) or None, not {mean_test!r}")
        # the mean of N white innovations of variance C_T has variance C_T / N: its square over that
        # is chi-square(1) when the filter is consistent
        self.mean_chi2 = None if mean_test is None else float(chi2_ppf(mean_test, 1))
        self.r0 = np.asarray(r0, dtype=float)
        self.r = self.r0.copy()
        self.N = int(window)
        self.compound = r_update == "compound"
        self.fuzzy = FuzzyAlpha(th or Thresholds())
        self.buf = np.zeros((3, self.N))  # eps^2 of the window (eq. 17)
        self.buf_e = np.zeros((3, self.N))  # eps of the window (its mean, for c_a="centered")
        self.s_e = np.zeros(3)  # running sum of buf_e (eq. 18's recursion applied to eps)
        self.count = np.zeros(3, dtype=int)
        self.c_a = np.zeros(3)
        self.r_floor = 1e-6 * self.r0
        self._rows = np.arange(3)
        self.hist = {k: np.full((n_steps, 3), np.nan) for k in ("r_hat", "c_a", "c_t", "dom", "alpha")}

    def inflation(self, ch: NDArray, hph_diag: NDArray) -> NDArray:
        """Per channel, the factor ``lambda >= 1`` for the predicted covariance: eq. 15's
        ``C_T = H P^- H^T + R`` must cover the innovation's systematic part too. When the window mean
        ``mu`` of the innovations is significant (``mu^2 > chi2_1(mean_test) C_T / N``, C_T with the
        current R_hat), ``lambda = mu^2 / (H P^- H^T)`` so that the state covariance holds at least
        the squared systematic error; else 1 (and always 1 before the window is full or without
        ``mean_test``). The centred C_A (``c_a="centered"``) gives R the zero-mean part."""
        lam = np.ones(len(ch))
        m = self.count[ch]
        if self.mean_chi2 is None or m.min() < self.N:
            return lam
        mu = self.s_e[ch] / self.N
        mu2 = mu * mu
        sig = mu2 > self.mean_chi2 * (hph_diag + self.r[ch]) / self.N
        return np.where(sig, np.maximum(1.0, mu2 / hph_diag), 1.0)

    def r_current(self, ch: NDArray | slice) -> NDArray:
        """The R it holds now per channel (the last R_hat), for the filter's innovation gate."""
        return self.r[ch].copy()

    def __call__(self, k: int, ch: NDArray | slice, eps: NDArray, HPH: NDArray, r0_rows: NDArray) -> NDArray:
        e2 = eps * eps
        cnt = self.count[ch]
        slot = cnt % self.N
        rows = self._rows[ch]
        old = self.buf[rows, slot]
        old_e = self.buf_e[rows, slot]
        self.buf[rows, slot] = e2
        self.buf_e[rows, slot] = eps
        cnt = cnt + 1
        self.count[ch] = cnt
        if cnt.min() > self.N:  # eq. 18: add the newest, drop the one leaving the window
            c_a = self.c_a[ch] + (e2 - old) / self.N
            s_e = self.s_e[ch] + (eps - old_e)
        else:  # filling the window (eq. 17 over what is there)
            c_a = self.c_a[ch] + (e2 - self.c_a[ch]) / np.minimum(cnt, self.N)
            c_a = np.where(cnt > self.N, self.c_a[ch] + (e2 - old) / self.N, c_a)
            s_e = self.s_e[ch] + eps - np.where(cnt > self.N, old_e, 0.0)
        self.c_a[ch] = c_a  # eq. 17: the window's second moment of eps
        self.s_e[ch] = s_e
        if self.centered:  # the window's covariance of eps about its mean (unbiased, n - 1)
            m = np.minimum(cnt, self.N)
            mean = s_e / m
            c_a = np.maximum(c_a - mean * mean, 0.0) * m / np.maximum(m - 1, 1)
        r_prev = self.r[ch]
        c_t = HPH.diagonal() + r_prev  # eq. 15
        dom = c_a / c_t  # eq. 20
        alpha = self.fuzzy(dom)
        if cnt.min() < self.N:
            alpha = np.where(cnt >= self.N, alpha, 1.0)
        r_hat = alpha * (r_prev if self.compound else self.r0[ch])  # eq. 21
        r_hat = np.maximum(r_hat, self.r_floor[ch])  # numerical safety only
        self.r[ch] = r_hat
        h = self.hist
        h["r_hat"][k, ch], h["c_a"][k, ch], h["c_t"][k, ch] = r_hat, c_a, c_t
        h["dom"][k, ch], h["alpha"][k, ch] = dom, alpha
        return r_hat


def run_fuzzy_ukf(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    """fuzzy-ukf; ``bias``: ``"auto"`` (default: bias states when the IMU has a bias,
    :func:`graphnav.estimators.imu_model.wants_bias`), true or false (the paper's 5-state filter)."""
    return _run(log, "fuzzy-ukf", on_estimate, options)


def _run(log: NavLog, name: str, on_estimate: OnEstimate | None, options: dict[str, Any]) -> RunResult:
    options = dict(options)
    window = int(options.pop("window", 30))
    r_update = str(options.pop("r_update", "compound"))
    c_a = str(options.pop("c_a", "centered"))
    auto_bias, _ = wants_bias(log)
    bias = resolve_flag(options.pop("bias", "auto"), auto_bias, "bias")
    # with bias states the model error is estimated in the state: no inflation by default
    mean_test = options.pop("mean_test", None if bias else 0.95)
    mean_test = None if mean_test is None else float(mean_test)

    o = {**DEFAULTS, **options}
    tab = measurement_table(log)
    rk = channel_variances(tab, o)[:, :3]
    # the prior R per channel: the records' (median) variance, or the options' (Table 2)
    r0 = np.array([np.nanmedian(rk[:, j]) if np.isfinite(rk[:, j]).any() else 1.0 for j in range(3)])
    n = len(tab["t"])
    matcher = FuzzyCovarianceMatcher(r0, n, window=window, r_update=r_update, c_a=c_a, mean_test=mean_test)
    res = run_nav_filter(log, name, bias=bias, adapter=matcher,
                         on_estimate=on_estimate, options=options)
    res.info["options"].update(window=window, r_update=r_update, bias=bias, c_a=c_a, mean_test=mean_test)
    res.info.update(matcher.hist)
    res.info["r0"] = r0
    return res


def run_fuzzy_ukf_bias(log: NavLog, *, on_estimate: OnEstimate | None = None, **options: Any) -> RunResult:
    return _run(log, "fuzzy-ukf-bias", on_estimate, {**options, "bias": True})


@dataclass
class FuzzyUkfBiasConfig(UkfOptions):
    """The ``fuzzy-ukf-bias`` estimator's options: the fuzzy adaptation's and the UKF's."""

    group: ClassVar[str] = "fuzzy"
    window: int = option(30, "innovations in the covariance-matching window (N)")
    r_update: str = option("compound", "compound (R(k) adapts recursively) or scale_prior (alpha scales R_0)")
    c_a: str = option("centered", "centered (C_A = the window's innovation covariance about its mean) or raw (eq. "
                      "17's second moment, which also books model error as sensor noise)")
    mean_test: float | None = option(None, "confidence level of the test of the innovations' window mean; when "
                                     "significant the predicted covariance is inflated to cover it (null: off)")


@dataclass
class FuzzyUkfConfig(FuzzyUkfBiasConfig):
    """The ``fuzzy-ukf`` estimator's options (``mean_test`` 0.95 unless the filter has bias states)."""

    mean_test: float | None = option(0.95, "confidence level of the test of the innovations' window mean; when "
                                     "significant the predicted covariance is inflated to cover it (null: off; "
                                     "default null when the filter has bias states)")
    bias: bool | str = option("auto", "IMU bias states: auto (unless meta['imu'] says bias_free; then as "
                              "fuzzy-ukf-bias), true, false (with compass_bias=false: the paper's 5-state filter)")


class FuzzyUkf(Ukf):
    """The UKF with fuzzy covariance-matching R adaptation (:func:`run_fuzzy_ukf`); the UKF's inputs."""

    description = "UKF with fuzzy covariance-matching R adaptation (Liu 2019)"
    Config = FuzzyUkfConfig
    batch = staticmethod(run_fuzzy_ukf)


class FuzzyUkfBias(FuzzyUkf):
    """fuzzy-ukf on the bias-augmented state (:func:`run_fuzzy_ukf_bias`)."""

    description = "fuzzy-ukf on the bias-augmented ukf-bias state (ours)"
    Config = FuzzyUkfBiasConfig
    batch = staticmethod(run_fuzzy_ukf_bias)


ESTIMATORS = {"fuzzy-ukf": FuzzyUkf, "fuzzy-ukf-bias": FuzzyUkfBias}
