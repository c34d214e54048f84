"""Mean of a correlated force record over a steady window, with its uncertainty.

Ice-force samples are strongly correlated in time (a contact lasts many output
intervals), so the naive standard error sigma/sqrt(n) is too small by
sqrt(tau_int). Two standard estimators are used:

* the integrated autocorrelation time ``tau_int = 1 + 2 sum_k rho_k`` (in
  samples) with Sokal's automatic window: the sum stops at the first lag M with
  M >= c tau_int(M), c = 5 (A. Sokal, "Monte Carlo methods in statistical
  mechanics", Cargese lectures 1996, section 3). For an AR(1) process
  x_t = a x_{t-1} + e_t, tau_int = (1 + a)/(1 - a); var(mean) = var(x) tau_int / n.
* batch means (Schmeiser 1982, Oper. Res. 30, 556): the window is cut into B
  equal batches; the batch means are nearly independent once a batch is much
  longer than tau_int, so their spread gives the standard error of the mean and
  a Student-t interval with B - 1 degrees of freedom.

The batch count is chosen from tau_int: batches of about 10 tau_int, between 10
and 32 of them; fewer than 10 batches of at least 5 tau_int (or fewer than 100
samples) is refused, since
the interval would then be too narrow (the batch-means variance is biased low by
about tau_int / (2 b) for a batch of b samples).

All functions take samples along the last axis, so many records can be
processed at once (used by the coverage tests).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from iceresist.errors import InputError
from iceresist.post.window import select_window

log = logging.getLogger(__name__)

#: Sokal's window constant c: the autocorrelation sum stops at the first lag M >= c tau_int(M).
SOKAL_WINDOW_C = 5.0
#: Fewest batches accepted for an automatic batch count (Student t with 9 dof).
MIN_BATCHES = 10
#: Most batches used by the automatic batch count.
MAX_BATCHES = 32
#: Target batch length of the automatic batch count, in units of tau_int.
BATCH_LENGTH_TAU = 10.0
#: Shortest batch accepted by the automatic batch count, in units of tau_int (tau_int taken >= 1).
MIN_BATCH_LENGTH_TAU = 5.0
#: Fewest samples in a window for the automatic batch count (the tau_int estimate needs a long record).
MIN_SAMPLES = 100


def autocorrelation(x) -> np.ndarray:
    """Normalised autocorrelation rho_k, k = 0..n-1, along the last axis (FFT, biased estimator).

    A constant record (std below 1e-12 of its magnitude) has rho = (1, 0, 0, ...).
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    d = x - x.mean(axis=-1, keepdims=True)
    nfft = 1 << (2 * n - 1).bit_length()
    spec = np.fft.rfft(d, nfft, axis=-1)
    acov = np.fft.irfft(spec * spec.conj(), nfft, axis=-1)[..., :n] / n
    var = acov[..., :1]
    flat = var <= 1e-24 * np.max(np.abs(x), axis=-1, keepdims=True) ** 2
    safe = np.where(flat, 1.0, var)
    rho = acov / safe
    return np.where(flat, np.eye(1, n)[0], rho)


def integrated_autocorrelation_time(x, c: float = SOKAL_WINDOW_C) -> np.ndarray | float:
    """Integrated autocorrelation time tau_int [samples] along the last axis (Sokal's automatic window).

    tau_int = 1 + 2 sum_{k=1}^{M} rho_k with M the first lag where M >= c tau_int(M).
    With the biased autocovariance the sum over all lags is exactly -1/2, so
    tau_int(M) falls to 0 at the last lag and such an M always exists; on a
    record shorter than a few tau_int it comes early and the estimate is too
    low, but still of order n / c, which the batch-length check then refuses.
    Returns a float for a 1-D input, an array otherwise.
    """
    rho = autocorrelation(x)
    n = rho.shape[-1]
    tau_m = 1.0 + 2.0 * np.cumsum(rho[..., 1:], axis=-1)  # tau_int(M) for M = 1..n-1
    if n < 2:
        tau = np.ones(rho.shape[:-1])
    else:
        lags = np.arange(1, n)
        ok = lags >= c * tau_m
        first = np.where(ok.any(axis=-1), ok.argmax(axis=-1), n - 2)
        tau = np.take_along_axis(tau_m, first[..., None], axis=-1)[..., 0]
    tau = np.maximum(tau, 1.0 / n)
    return float(tau) if np.ndim(tau) == 0 else tau


@dataclass(frozen=True)
class BatchMeans:
    """Batch-means estimate (arrays for many records, floats for one).

    Attributes:
        mean: mean over the samples used (unit of the input).
        stderr: standard error of that mean from the spread of the batch means.
        ci_half_width: half width of the two-sided Student-t interval, B - 1 dof.
        n_batches: batch count B.
        batch_length: samples per batch b.
        n_used: samples used, B * b (the earliest n - B b samples are dropped).
    """

    mean: np.ndarray | float
    stderr: np.ndarray | float
    ci_half_width: np.ndarray | float
    n_batches: int
    batch_length: int
    n_used: int


def batch_means(x, n_batches: int, confidence: float = 0.95) -> BatchMeans:
    """Batch-means mean, standard error and Student-t interval along the last axis.

    The record is cut into ``n_batches`` batches of ``b = n // n_batches``
    samples; the first ``n - n_batches b`` samples (the oldest, nearest the
    transient) are dropped. stderr = std(batch means, ddof=1) / sqrt(B);
    interval = mean +- t_{(1+confidence)/2, B-1} stderr.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    _check_confidence(confidence)
    if int(n_batches) != n_batches or n_batches < 2:
        raise InputError(f"n_batches={n_batches!r} must be an integer >= 2")
    n_batches = int(n_batches)
    b = n // n_batches
    if b < 1:
        raise InputError(f"n_batches={n_batches} exceeds the {n} samples of the window: use fewer batches")
    used = x[..., n - n_batches * b:]
    bm = used.reshape(*x.shape[:-1], n_batches, b).mean(axis=-1)
    mean = bm.mean(axis=-1)
    stderr = np.sqrt(bm.var(axis=-1, ddof=1) / n_batches)
    t_crit = float(stats.t.ppf(0.5 + 0.5 * confidence, n_batches - 1))
    half = t_crit * stderr
    if np.ndim(mean) == 0:
        mean, stderr, half = float(mean), float(stderr), float(half)
    return BatchMeans(mean, stderr, half, n_batches, b, n_batches * b)


def choose_n_batches(n_samples: int, tau_int: float, label: str = "window") -> int:
    """Automatic batch count: batches of about BATCH_LENGTH_TAU tau_int, MIN_BATCHES..MAX_BATCHES of them.

    Raises InputError when the window holds fewer than MIN_SAMPLES samples or
    fewer than MIN_BATCHES batches of MIN_BATCH_LENGTH_TAU max(tau_int, 1) fit.
    """
    b_min = math.ceil(MIN_BATCH_LENGTH_TAU * max(tau_int, 1.0))
    needed = max(MIN_SAMPLES, MIN_BATCHES * b_min)
    if n_samples < needed:
        raise InputError(
            f"{label} holds {n_samples} samples, too few for batch means: with tau_int = {tau_int:.3g} samples "
            f"it needs at least {needed} ({MIN_BATCHES} batches of >= {b_min}, >= {MIN_SAMPLES} in all); "
            "widen the window or sample more often"
        )
    b_target = max(1, math.ceil(BATCH_LENGTH_TAU * tau_int))
    return int(min(MAX_BATCHES, max(MIN_BATCHES, n_samples // b_target)))


@dataclass(frozen=True)
class PooledMean:
    """Mean of one stationary quantity over independent records, from their pooled batch means.

    Attributes:
        mean: the mean over the batches' samples (each batch weighted by its length).
        stderr: its standard error from the spread of the batch means (weighted, N - 1 dof).
        ci_half_width: half width of the Student-t interval, N - 1 dof.
        n_batches: batches N of all records.
        record_means: each record's mean over its batches' samples.
        batches: batches per record.
    """

    mean: float
    stderr: float
    ci_half_width: float
    n_batches: int
    record_means: tuple
    batches: tuple

    @property
    def too_few_batches(self) -> bool:
        """Fewer than MIN_BATCHES batches: the interval's own spread is poorly known."""
        return self.n_batches < MIN_BATCHES


def pooled_batch_means(records, tau_int_samples, confidence: float = 0.95) -> PooledMean:
    """Mean and Student-t interval of independent records of one stationary quantity (runs of one case from
    independent starts, e.g. ice arrangements of other seeds): each record cut into as many batches of at least
    MIN_BATCH_LENGTH_TAU of its ``tau_int_samples`` as it holds (one batch where it holds fewer; its oldest
    samples dropped, as :func:`batch_means` does), the batch means of all records pooled. Batches of two records
    are independent (the runs share no state); those of one record, five correlation times long, nearly so. With
    batch j of length b_j and mean m_j: mean = sum b_j m_j / B, B = sum b_j; stderr^2 = sum b_j (m_j - mean)^2 /
    ((N - 1) B) (each m_j's variance taken as s^2 / b_j); interval mean +- t_{(1+confidence)/2, N-1} stderr."""
    _check_confidence(confidence)
    records = [np.asarray(r, dtype=float) for r in records]
    taus = [float(t) for t in np.atleast_1d(tau_int_samples)]
    if len(records) != len(taus) or not records:
        raise InputError(f"pooled_batch_means: {len(records)} records and {len(taus)} tau_int values; give one "
                         "tau_int per record")
    means, lengths, per_record, record_means = [], [], [], []
    for x, tau in zip(records, taus):
        n = len(x)
        if n < 1:
            raise InputError("pooled_batch_means: a record holds no sample")
        k = max(1, int(n // math.ceil(MIN_BATCH_LENGTH_TAU * max(tau, 1.0))))
        b = n // k
        used = x[n - k * b:].reshape(k, b)
        means.extend(used.mean(axis=1))
        lengths.extend([b] * k)
        per_record.append(k)
        record_means.append(float(used.mean()))
    m, w = np.asarray(means), np.asarray(lengths, dtype=float)
    nb = len(m)
    if nb < 2:
        raise InputError("pooled_batch_means: one batch in all; give more records or longer ones")
    mean = float((w * m).sum() / w.sum())
    stderr = float(np.sqrt((w * (m - mean) ** 2).sum() / ((nb - 1) * w.sum())))
    half = float(stats.t.ppf(0.5 + 0.5 * confidence, nb - 1)) * stderr
    return PooledMean(mean, stderr, half, nb, tuple(record_means), tuple(per_record))


@dataclass(frozen=True)
class SteadyMean:
    """Mean of a force over a steady window with its batch-means uncertainty.

    Force fields carry the unit of the input record (``_N`` when the record is in newtons).

    Attributes:
        mean_N: time mean over the samples used [N].
        stderr_N: standard error of the mean from batch means [N].
        ci_low_N, ci_high_N: two-sided confidence interval of the mean [N] (Student t, n_batches - 1 dof).
        ci_half_width_N: half width of that interval [N].
        confidence: confidence level of the interval (0.95 by default).
        std_N: standard deviation of the samples in the window [N].
        tau_int_samples: integrated autocorrelation time [samples] (Sokal window).
        tau_int_s: the same in seconds [s].
        n_samples: samples in the window.
        n_used: samples used by the batches (the earliest n_samples - n_used dropped).
        n_effective: effective number of independent samples, n_samples / tau_int_samples.
        n_batches: batch count B.
        batch_length: samples per batch.
        dof: degrees of freedom of the interval, B - 1.
        dt_s: sampling interval [s].
        t_start_s, t_end_s: first and last time of the samples used [s].
        window: the window as given (text).
    """

    mean_N: float
    stderr_N: float
    ci_low_N: float
    ci_high_N: float
    ci_half_width_N: float
    confidence: float
    std_N: float
    tau_int_samples: float
    tau_int_s: float
    n_samples: int
    n_used: int
    n_effective: float
    n_batches: int
    batch_length: int
    dof: int
    dt_s: float
    t_start_s: float
    t_end_s: float
    window: str

    @property
    def interval_too_narrow(self) -> bool:
        """Batches shorter than MIN_BATCH_LENGTH_TAU tau_int: the interval is likely too narrow."""
        return self.batch_length < MIN_BATCH_LENGTH_TAU * self.tau_int_samples

    def to_dict(self) -> dict:
        """Plain dict of the fields (for JSON and DataFrames)."""
        return dataclasses.asdict(self)

    def __str__(self) -> str:
        pct = round(100 * self.confidence)
        return (
            f"{self.mean_N:.6g} N +- {self.ci_half_width_N:.3g} N ({pct} % CI, {self.n_batches} batches), "
            f"tau_int = {self.tau_int_s:.3g} s, n_eff = {self.n_effective:.1f}, {self.window}"
        )


def _check_confidence(confidence: float) -> None:
    if not (0.0 < float(confidence) < 1.0):
        raise InputError(f"confidence={confidence!r} must lie strictly between 0 and 1 (e.g. 0.95)")


def steady_mean(t_s, F_N, *, window_s=None, window_m=None, x_ship_m=None, n_batches: int | None = None,
                confidence: float = 0.95, signal_name: str = "F_N", warn_short_batches: bool = True) -> SteadyMean:
    """Mean of the force record ``F_N(t_s)`` over a steady window with its batch-means confidence interval.

    Args:
        t_s: sample times [s], strictly increasing and uniform.
        F_N: force samples [N] (any unit passes through).
        window_s: steady window as a time range (t0, t1) [s]; or
        window_m: steady window as a ship-position range (x0, x1) [m], with
        x_ship_m: ship position at each sample [m].
        n_batches: batch count; None chooses it from tau_int (:func:`choose_n_batches`).
        confidence: confidence level of the interval.
        signal_name: name of the signal in error messages.
        warn_short_batches: log a warning when a given ``n_batches`` makes batches shorter than
            MIN_BATCH_LENGTH_TAU tau_int (the result's ``interval_too_narrow`` says so either way).

    Raises:
        InputError: empty window, window outside the record, too few samples,
            non-monotonic or non-uniform time, NaN/inf in the signal.
    """
    _check_confidence(confidence)
    w = select_window(t_s, F_N, window_s=window_s, window_m=window_m, x_ship_m=x_ship_m,
                      signal_name=signal_name)
    y = w.values
    n = y.size
    if n < 2:
        raise InputError(f"{w.label} holds {n} sample: batch means needs at least {MIN_SAMPLES}")
    tau = integrated_autocorrelation_time(y)
    if n_batches is None:
        n_batches = choose_n_batches(n, tau, w.label)
    else:
        if int(n_batches) != n_batches or n_batches < 2:
            raise InputError(f"n_batches={n_batches!r} must be an integer >= 2")
        if warn_short_batches and n // int(n_batches) < MIN_BATCH_LENGTH_TAU * tau:
            log.warning(
                "%s: batches of %d samples are shorter than %.0f tau_int = %.3g samples; "
                "the interval is likely too narrow", w.label, n // int(n_batches), MIN_BATCH_LENGTH_TAU,
                MIN_BATCH_LENGTH_TAU * tau,
            )
    bm = batch_means(y, int(n_batches), confidence)
    t_used = w.t_s[n - bm.n_used:]
    return SteadyMean(
        mean_N=bm.mean,
        stderr_N=bm.stderr,
        ci_low_N=bm.mean - bm.ci_half_width,
        ci_high_N=bm.mean + bm.ci_half_width,
        ci_half_width_N=bm.ci_half_width,
        confidence=float(confidence),
        std_N=float(np.std(y, ddof=1)),
        tau_int_samples=float(tau),
        tau_int_s=float(tau) * w.dt_s,
        n_samples=int(n),
        n_used=int(bm.n_used),
        n_effective=float(n / tau),
        n_batches=bm.n_batches,
        batch_length=bm.batch_length,
        dof=bm.n_batches - 1,
        dt_s=w.dt_s,
        t_start_s=float(t_used[0]),
        t_end_s=float(t_used[-1]),
        window=w.label,
    )
