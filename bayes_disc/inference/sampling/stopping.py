"""The stopping rule: integrated autocorrelation time τ, R-hat across ensembles and bulk ESS of the coefficients
after burn-in (:func:`convergence`), the warm-up before the first check and how far a check is from the rule.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import emcee
import numpy as np
import scipy.fft

from ..model.config import SamplerSettings
from . import mcmc_stats
from .chains import _InMemoryChains


#: re-fits of the Gaussian reference (and of the independence proposal's weights) during warm-up
ADAPTATIONS = 2


#: most float64 values of one batch of FFTs in :func:`_tau` (bounds its memory: 2²⁴ values, 128 MB complex)
TAU_BATCH_VALUES = 1 << 24


def _tau(chain: np.ndarray, c: float = 5.0, workers: int = 1) -> np.ndarray:
    """Integrated autocorrelation time per parameter (steps): emcee's estimator (walker-averaged
    autocorrelation function, Sokal's automatic window c), skipping walkers that did not move in the
    window (their autocorrelation is undefined; emcee would return NaN).

    The autocorrelation functions are ``emcee.autocorr.function_1d``'s (the centred series' FFT, zero-padded
    so that the circular correlation is the linear one, normalised at lag 0), computed for every walker and
    parameter of a batch at once (at most :data:`TAU_BATCH_VALUES` transform values) with the shortest fast
    padding ≥ 2·n_steps − 1 instead of emcee's 2·next power of two: the same numbers to rounding
    (tests/test_sampler_tau.py), and several times faster.

    Parameters
    ----------
    chain : (n_steps, n_walkers, dim) array
        One ensemble's steps.
    c : float
        Sokal's window constant.
    workers : int
        Threads of the FFTs (the convergence check runs while the sampling processes wait).

    Returns
    -------
    (dim,) array
        τ [steps]; inf for a parameter no walker moved in.
    """
    n_steps, n_w, dim = chain.shape
    n_fft = scipy.fft.next_fast_len(2 * n_steps - 1, real=True)
    per = max(1, TAU_BATCH_VALUES // (n_fft * n_w))            # parameters per batch
    tau = np.empty(dim)
    for lo in range(0, dim, per):
        x = np.moveaxis(chain[:, :, lo: lo + per], 0, -1)      # (n_w, p, n_steps): time contiguous
        moved = np.ptp(x, axis=-1) > 0                         # (n_w, p)
        x = x - x.mean(axis=-1, keepdims=True)
        norm = np.sqrt(np.einsum("wpt,wpt->wp", x, x))         # √(lag-0 autocovariance · n_steps)
        x /= np.where(moved, norm, 1.0)[..., None]             # unit lag 0: each walker's ACF is normalised
        x[~moved] = 0.0                                        # a walker that stayed put has none
        f = scipy.fft.rfft(x, n=n_fft, axis=-1, workers=workers)
        power = np.einsum("wpk->pk", f.real ** 2 + f.imag ** 2)  # Σ over walkers: the transform is linear
        acf = scipy.fft.irfft(power, n=n_fft, axis=-1, workers=workers)[:, :n_steps]
        used = moved.sum(axis=0)                               # (p,)
        taus = 2.0 * np.cumsum(acf / np.maximum(used, 1)[:, None], axis=-1) - 1.0
        for j in range(x.shape[1]):
            tau[lo + j] = np.inf if used[j] == 0 else taus[j, emcee.autocorr.auto_window(taus[j], c)]
    return tau


#: most parameters per block in the convergence statistics
CHECK_BLOCK = 32
#: most draws (ensembles × steps × walkers × parameters) per block: bounds the rank and FFT work arrays
#: (≈ 10 arrays of this many values per block in flight; 2²² values: 32 MB each)
CHECK_VALUES = 1 << 22


def convergence(chain, settings: SamplerSettings, coef_idx: np.ndarray, first_step: int = 0):
    """Burn-in, τ, R-hat and ESS; returns a verdict dict.

    Parameters
    ----------
    chain : (n_ens, n, n_walkers, dim) array or StoredChains
        The ensembles' steps from ``first_step`` on (the warm-up before it is burn-in); stored chains are
        read a block of parameters at a time (:class:`.chains.StoredChains`).
    settings : SamplerSettings
    coef_idx : (k,) int array
        Parameters whose bulk ESS must reach ``settings.ess``.
    first_step : int
        Step number of ``chain[:, 0]``.

    Returns
    -------
    dict
        ``burn`` (absolute step: the warm-up and at least 5 τ after it, at most half of what follows it),
        ``tau`` (n_ens, dim), ``n_over_tau``, ``rhat_max`` (every parameter; the rule's), ``rhat_max_coef``
        (the coefficients'), ``ess_min_coef``, ``converged``. Every statistic
        is computed per parameter, in blocks of at most :data:`CHECK_BLOCK` parameters and
        :data:`CHECK_VALUES` draws (``settings.processes`` blocks at once, in threads: the sampling
        processes wait during a check), so memory stays bounded as the chains grow: two passes over the
        blocks, τ on the whole window (for the burn-in), then τ, R-hat and ESS after it.
    """
    source = chain if hasattr(chain, "block") else _InMemoryChains(np.asarray(chain))
    n_ens, n, n_w, dim = source.shape
    workers = max(1, settings.processes)
    per = max(1, min(CHECK_BLOCK, CHECK_VALUES // (n_ens * n * n_w)))
    blocks = [slice(j, min(j + per, dim)) for j in range(0, dim, per)]
    coef = np.zeros(dim, bool)
    coef[np.asarray(coef_idx)] = True

    with ThreadPoolExecutor(max_workers=workers) as threads:     # the sorts and FFTs release the GIL
        def tau_of(x):
            return np.array([_tau(x[e]) for e in range(n_ens)])             # (n_ens, block)

        tau0 = np.concatenate(list(threads.map(lambda b: tau_of(source.block(0, b)), blocks)), axis=1)
        skip = int(min(np.ceil(5 * np.nanmax(tau0)), n // 2))

        def after_burn(b):
            x = source.block(skip, b)
            wanted = np.flatnonzero(coef[b])                        # the rule asks ESS of the coefficients alone
            return (tau_of(x), mcmc_stats.rhat(x, layout="ensembles"),
                    mcmc_stats.ess(x[..., wanted], layout="walkers") if wanted.size else np.zeros(0))

        parts = list(threads.map(after_burn, blocks))
    tau = np.concatenate([p[0] for p in parts], axis=1)
    rh = np.concatenate([p[1] for p in parts])
    ess = np.concatenate([p[2] for p in parts])
    n_over_tau = (n - skip) / np.nanmax(tau)
    ok = (first_step + n >= settings.min_steps and n_over_tau >= settings.n_tau and np.all(rh < settings.rhat)
          and np.all(ess >= settings.ess))
    return {"burn": first_step + skip, "tau": tau, "n_over_tau": float(n_over_tau), "rhat_max": float(np.max(rh)),
            "rhat_max_coef": float(np.max(rh[coef])), "ess_min_coef": float(np.min(ess)),
            "converged": bool(ok)}


def warm_up_steps(settings: SamplerSettings) -> int:
    """Steps before the first convergence check: the warm-up adaptations and one round of ``check_every``.

    Parameters
    ----------
    settings : SamplerSettings
        The sampler settings.

    Returns
    -------
    int
        Steps of every ensemble.
    """
    return settings.adapt_steps * ADAPTATIONS + settings.check_every


def convergence_fraction(verdict: dict, settings: SamplerSettings, steps: int) -> float:
    """How far the ensembles are toward the stopping rule: the worst of its criteria, each as a fraction.

    R-hat: (rhat − 1) / (R-hat_max − 1) (1 when R-hat max reaches the target); ESS: min coefficient bulk
    ESS / ``ess``; N/τ: (N/τ) / ``n_tau``; steps: ``steps`` / ``min_steps``. The rule is met exactly when
    every fraction reaches 1 (R-hat strictly below its target), so the result is 1 only then.

    Parameters
    ----------
    verdict : dict
        A convergence check (:func:`convergence`): ``rhat_max``, ``ess_min_coef``, ``n_over_tau``,
        ``converged``.
    settings : SamplerSettings
        Targets ``rhat``, ``ess``, ``n_tau``, ``min_steps``.
    steps : int
        Steps done by every ensemble.

    Returns
    -------
    float
        In [0, 1]; 1 if and only if ``verdict["converged"]``.
    """
    if verdict["converged"]:
        return 1.0
    excess = verdict["rhat_max"] - 1.0
    parts = [(settings.rhat - 1.0) / excess if excess > 0 else (1.0 if excess <= 0 else np.nan),
             verdict["ess_min_coef"] / settings.ess,
             verdict["n_over_tau"] / settings.n_tau,
             steps / max(settings.min_steps, 1)]
    finite = [p if np.isfinite(p) else 0.0 for p in parts]
    # not converged: at least one criterion is unmet, so stay below 1 even when rounding says otherwise
    return float(min(min(finite), 0.999))
