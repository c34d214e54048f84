"""Statistical self-check of the steady-mean estimator on signals with known answers.

Stationary AR(1) records x_t = a x_{t-1} + e_t have tau_int = (1 + a)/(1 - a)
and a known true mean, so the estimated tau_int and the coverage of the stated
confidence interval can be measured. Run::

    python -m iceresist.post.selfcheck [--reps 1000] [--length-tau 200] [--seed 1] [--json]

Records are ``length_tau`` true autocorrelation times long. Records that the
automatic batch count refuses (too short for the estimated tau_int) are
counted and left out of the coverage. It prints one line (or one JSON object)
per AR(1) coefficient.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from scipy.signal import lfilter

from iceresist.errors import InputError
from iceresist.post.statistics import integrated_autocorrelation_time, steady_mean


def ar1_records(rng: np.random.Generator, a: float, reps: int, n: int) -> np.ndarray:
    """``reps`` stationary AR(1) records of ``n`` samples (unit innovations), shape (reps, n)."""
    e = rng.standard_normal((reps, n))
    e[:, 0] /= np.sqrt(1.0 - a * a)
    return lfilter([1.0], [1.0, -a], e, axis=-1)


def check_ar1(a: float, reps: int, length_tau: float, seed: int, n_tau: int = 2**17) -> dict:
    """Coverage of the 95 % interval over ``reps`` records of ``length_tau`` tau_int, and tau_int of a long record."""
    rng = np.random.default_rng(seed)
    tau_true = (1.0 + a) / (1.0 - a)
    n = int(np.ceil(length_tau * tau_true))
    tau_long = float(integrated_autocorrelation_time(ar1_records(rng, a, 1, n_tau)[0]))
    x = ar1_records(rng, a, reps, n)
    t = np.arange(n, dtype=float)
    start = time.perf_counter()
    results, refused = [], 0
    for xi in x:
        try:
            results.append(steady_mean(t, xi))
        except InputError:
            refused += 1
    seconds = time.perf_counter() - start
    covered = float(np.mean([r.ci_low_N <= 0.0 <= r.ci_high_N for r in results]))
    accepted = len(results)
    taus = np.array([r.tau_int_samples for r in results])
    sigma_x = 1.0 / np.sqrt(1.0 - a * a)
    stderr_rms = float(np.sqrt(np.mean([r.stderr_N**2 for r in results])))
    stderr_true = sigma_x * np.sqrt(tau_true / results[0].n_used)
    return {
        "a": a,
        "tau_int_true": tau_true,
        "tau_int_long_record": tau_long,
        "n_long_record": n_tau,
        "reps": reps,
        "n": n,
        "refused": refused,
        "tau_int_mean": float(taus.mean()),
        "tau_int_std": float(taus.std(ddof=1)),
        "n_batches_mean": float(np.mean([r.n_batches for r in results])),
        "coverage_95": covered,
        "coverage_binomial_se": float(np.sqrt(covered * (1 - covered) / accepted)),
        "stderr_rms_over_true": stderr_rms / stderr_true,
        "seconds": seconds,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m iceresist.post.selfcheck", description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=1000, help="records per AR(1) coefficient")
    parser.add_argument("--length-tau", type=float, default=200.0, help="record length in true tau_int")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--a", type=float, nargs="+", default=[0.5, 0.9, 0.97], help="AR(1) coefficients")
    parser.add_argument("--json", action="store_true", help="one JSON object per coefficient")
    args = parser.parse_args(argv)
    for a in args.a:
        r = check_ar1(a, args.reps, args.length_tau, args.seed)
        if args.json:
            print(json.dumps(r))
        else:
            print(f"a={a:g}: tau_int true {r['tau_int_true']:.2f}, long record {r['tau_int_long_record']:.2f}, "
                  f"{r['n']}-sample records {r['tau_int_mean']:.2f} +- {r['tau_int_std']:.2f}; "
                  f"95 % coverage {r['coverage_95']:.3f} +- {r['coverage_binomial_se']:.3f} "
                  f"over {r['reps'] - r['refused']} records ({r['refused']} refused, {r['n_batches_mean']:.1f} batches); "
                  f"rms stderr / true {r['stderr_rms_over_true']:.3f}; {r['seconds']:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
