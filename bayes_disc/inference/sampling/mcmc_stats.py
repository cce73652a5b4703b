"""Convergence statistics of ensemble chains (n_ensembles, n_steps, n_walkers, dim).

One R-hat function, :func:`rhat`, and one ESS function, :func:`ess`, whose ``layout`` says what a chain is:
the sampler's stopping rule computes R-hat across *ensembles* (``layout="ensembles"``: each ensemble one chain,
its walkers' draws pooled step by step, so split-R-hat splits in time) and bulk ESS with every walker a chain
(``layout="walkers"``: autocorrelation along steps). Both are the rank-normalised estimators of Vehtari et al. (2021), written here as ArviZ 0.23 writes them
(``az.rhat(method="rank")``, ``az.ess(method="bulk")``: the same ranks, back-transform, split, Geyer
sequences and floors) but for every parameter at once: ArviZ loops over the parameters in Python through
xarray, which took seconds per convergence check on the demo while the sampling processes waited. The
tests compare both with ArviZ to 1e-10 (tests/test_mcmc_stats.py). :func:`summary_diagnostics` gives
``az.summary(kind="diagnostics")``'s five columns the same way (summary.json's per-parameter diagnostics).

    z = Φ⁻¹((r − 3/8) / (S + 1/4))              r: average rank among the S draws of the parameter
    R̂ = √((B/W + n − 1) / n)                   W: mean within-chain variance, B: n × variance of chain means
    R-hat = max(R̂(z of the split chains), R̂(z of |split − median|))
    ESS = M·n / τ̂,  τ̂ = −1 + 2 Σ ρ̂_t         over Geyer's initial positive, then monotone, sequence

The ranks are found from the runs of repeated draws (an ensemble's walker repeats its position on every
rejected proposal): each run is ranked once and its normal score repeated over it (:func:`_z_and_median`),
the same numbers as sorting every draw, bit for bit (tests/test_mcmc_stats.py), and faster on long chains.
"""
from __future__ import annotations

import numpy as np
import scipy.fft
from scipy import special

#: Blom's offset of the rank back-transform
BLOM = 3 / 8


def _split(x: np.ndarray) -> np.ndarray:
    """(p, 2m, ⌊n/2⌋) from (p, m, n): each chain's first and last halves (the middle draw of odd n dropped)."""
    half = x.shape[2] // 2
    return np.concatenate([x[:, :, :half], x[:, :, x.shape[2] - half:]], axis=1)


def _average_ranks(flat: np.ndarray) -> np.ndarray:
    """1-based ranks along the last axis of (p, S), ties given their average rank (``scipy.stats.rankdata``
    with ``method="average"``, whose ``axis`` path loops in Python)."""
    p, size = flat.shape
    order = np.argsort(flat, axis=1)
    ordered = np.take_along_axis(flat, order, axis=1)
    new = np.ones((p, size), bool)
    new[:, 1:] = ordered[:, 1:] != ordered[:, :-1]                 # first of a run of equal values
    last = np.ones((p, size), bool)
    last[:, :-1] = new[:, 1:]                                      # last of a run
    idx = np.broadcast_to(np.arange(size), (p, size))
    start = np.maximum.accumulate(np.where(new, idx, 0), axis=1)   # 0-based first index of the run
    end = np.minimum.accumulate(np.where(last, idx, size - 1)[:, ::-1], axis=1)[:, ::-1]
    ranks = np.empty((p, size))
    np.put_along_axis(ranks, order, (start + end) / 2.0 + 1.0, axis=1)
    return ranks


def _z_scale(x: np.ndarray) -> np.ndarray:
    """Normal scores of every parameter's pooled draws (average ranks for ties); x (p, m, n)."""
    return _z_and_median(x)[0]


def _z_scale_sorted(x: np.ndarray) -> np.ndarray:
    """:func:`_z_scale` by sorting every draw (:func:`_average_ranks`): the reference the run-length version
    is tested against."""
    flat = x.reshape(x.shape[0], -1)
    q = (_average_ranks(flat) - BLOM) / (flat.shape[1] - 2 * BLOM + 1)
    return special.ndtri(q).reshape(x.shape)


def _z_and_median(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normal scores of every parameter's pooled draws and their median, x (p, m, n) finite, sorting only
    the runs of repeated draws along the last axis.

    An ensemble sampler's walker repeats its position whenever a proposal is rejected: at 24 flights a
    coefficient changed in 7 % of a walker's steps. Each run of equal consecutive draws is ranked once —
    the runs' values sorted, equal values merged, a group of c draws after b smaller ones getting the
    average rank b + (c + 1)/2 — and its score repeated over the run: the same ranks, scores and median
    as sorting all S = m·n draws (:func:`_z_scale_sorted`, ``np.median``), bit for bit, in a fraction
    of the time when the draws repeat. Returns z (p, m, n) and the medians (p,)."""
    p, m, n = x.shape
    size = m * n
    fresh = np.ones(x.shape, bool)
    fresh[:, :, 1:] = x[:, :, 1:] != x[:, :, :-1]               # first draw of a run
    flat, fresh = x.reshape(p, size), fresh.reshape(p, size)
    z = np.empty((p, size))
    median = np.empty(p)
    for j in range(p):
        at = np.flatnonzero(fresh[j])
        length = np.diff(np.append(at, size))
        order = np.argsort(flat[j, at])
        value, count = flat[j, at][order], length[order]
        new = np.ones(value.size, bool)
        new[1:] = value[1:] != value[:-1]
        group = np.cumsum(new) - 1
        in_group = np.bincount(group, weights=count)            # draws per distinct value (exact integers)
        rank = np.cumsum(in_group) - in_group + (in_group + 1) / 2.0
        score = np.empty(value.size)
        score[order] = special.ndtri((rank - BLOM) / (size - 2 * BLOM + 1))[group]
        z[j] = np.repeat(score, length)
        upto = np.cumsum(count)                                 # draws up to each sorted run
        if size % 2:
            median[j] = value[np.searchsorted(upto, size // 2, side="right")]
        else:
            lo, hi = value[np.searchsorted(upto, [size // 2 - 1, size // 2], side="right")]
            median[j] = np.mean(np.array([lo, hi]))             # as np.median: the mean of the middle two
    return z.reshape(x.shape), median


def _psrf(x: np.ndarray) -> np.ndarray:
    """Potential scale reduction factor (the R̂ formula) per parameter of x (p, m, n), chains as given."""
    n = x.shape[2]
    within = np.var(x, axis=2, ddof=1).mean(axis=1)
    between = n * np.var(x.mean(axis=2), axis=1, ddof=1)
    return np.sqrt((between / within + n - 1) / n)


def _valid(x: np.ndarray, min_chains: int) -> np.ndarray:
    """(p,) bool: finite and at least 4 draws and ``min_chains`` chains (ArviZ's conditions)."""
    ok = np.all(np.isfinite(x.reshape(x.shape[0], -1)), axis=1)
    return ok & (x.shape[2] >= 4) & (x.shape[1] >= min_chains)


#: what a chain is in :func:`rhat` and :func:`ess`: ``"chains"``: x is (p, n_chains, n_draws);
#: ``"ensembles"``: x is an ensemble sampler's chain (n_ensembles, n_steps, n_walkers, dim) and each ensemble is
#: one chain, its walkers' draws pooled step-major (the split halves are early and late steps);
#: ``"walkers"``: the same array with every walker of every ensemble a chain
LAYOUTS = ("chains", "ensembles", "walkers")


def _as_chains(x: np.ndarray, layout: str) -> np.ndarray:
    """(p, n_chains, n_draws) view of x in one of :data:`LAYOUTS`."""
    if layout == "chains":
        return x
    n_ens, n_steps, n_w, dim = x.shape
    if layout == "ensembles":
        return np.moveaxis(x.reshape(n_ens, n_steps * n_w, dim), 2, 0)      # step-major
    if layout == "walkers":
        return np.moveaxis(np.moveaxis(x, 2, 1).reshape(n_ens * n_w, n_steps, dim), 2, 0)
    raise ValueError(f"layout {layout!r}: expected one of {', '.join(LAYOUTS)}")


def rhat(x: np.ndarray, method: str = "rank", layout: str = "chains") -> np.ndarray:
    """Rank-normalised split R-hat of every parameter (``az.rhat(method="rank")``).

    Parameters
    ----------
    x : array
        (p, n_chains, n_draws), or an ensemble chain (n_ensembles, n_steps, n_walkers, dim) with
        ``layout="ensembles"`` (as the sampler's stopping rule and summary.json's ``r_hat``) or ``"walkers"``.
    method : str
        ``"rank"`` (the only one: max of the bulk and the folded tail R-hat of the rank-normalised split chains).
    layout : str
        What a chain is (:data:`LAYOUTS`).

    Returns
    -------
    (p,) or (dim,) array
        max(bulk, tail) R-hat; NaN where a parameter has non-finite draws, fewer than 2 chains or 4 draws.
    """
    if method != "rank":
        raise ValueError(f"R-hat method {method!r}: only 'rank' is implemented")
    if layout == "ensembles":
        n_ens, n_steps, n_w, _ = x.shape
        size = n_steps * n_w
        if not (size % 2 or size < 4 or n_ens < 2 or not np.all(np.isfinite(x))):
            return _psrf_pooled_ensembles(x)
    x = _as_chains(x, layout)
    out = np.full(x.shape[0], np.nan)
    ok = _valid(x, 2)
    if not ok.any():
        return out
    s = _split(x[ok])
    z, median = _z_and_median(s)
    out[ok] = np.maximum(_psrf(z), _psrf(_z_scale(np.abs(s - median[:, None, None]))))
    return out


def _psrf_pooled_ensembles(chain: np.ndarray) -> np.ndarray:
    """:func:`rhat` with ``layout="ensembles"`` for finite chains of an even number ≥ 4 of draws per ensemble
    and ≥ 2 ensembles: the split keeps every draw, so the ranks are those of all draws, computed with each
    walker's steps in a row (repeated positions are runs: :func:`_z_and_median`)."""
    n_ens, n_steps, n_w, dim = chain.shape
    size = n_steps * n_w
    walkers = np.ascontiguousarray(np.transpose(chain, (3, 0, 2, 1))).reshape(dim, n_ens * n_w, n_steps)

    def split_by_ensemble(y):
        """(dim, n_ens·n_w, n_steps) in walker order → the split ensembles' chains, step-major."""
        y = y.reshape(dim, n_ens, n_w, n_steps).transpose(0, 1, 3, 2).reshape(dim, n_ens, size)
        return _split(y)

    z, median = _z_and_median(walkers)
    folded = _z_scale(np.abs(walkers - median[:, None, None]))
    return np.maximum(_psrf(split_by_ensemble(z)), _psrf(split_by_ensemble(folded)))


def _autocov(x: np.ndarray) -> np.ndarray:
    """Autocovariance at every lag along the last axis (divided by n), zero-padded FFT."""
    n = x.shape[-1]
    m = scipy.fft.next_fast_len(2 * n)
    f = scipy.fft.rfft(x - x.mean(axis=-1, keepdims=True), n=m, axis=-1)
    return scipy.fft.irfft(f.real ** 2 + f.imag ** 2, n=m, axis=-1)[..., :n] / n


def _geyer_effective_draws(mean_acov: np.ndarray, var_plus: float, mean_var: float, size: int) -> float:
    """ESS of one parameter from its chain-averaged autocovariance (ArviZ's ``_ess`` after the FFT)."""
    n = mean_acov.size
    rho = np.zeros(n)
    rho_even = 1.0
    rho[0] = rho_even
    rho_odd = 1.0 - (mean_var - mean_acov[1]) / var_plus
    rho[1] = rho_odd
    t = 1
    while t < n - 3 and rho_even + rho_odd > 0.0:          # Geyer's initial positive sequence
        rho_even = 1.0 - (mean_var - mean_acov[t + 1]) / var_plus
        rho_odd = 1.0 - (mean_var - mean_acov[t + 2]) / var_plus
        if rho_even + rho_odd >= 0:
            rho[t + 1] = rho_even
            rho[t + 2] = rho_odd
        t += 2
    max_t = t - 2
    if rho_even > 0:
        rho[max_t + 1] = rho_even
    t = 1
    while t <= max_t - 2:                                   # Geyer's initial monotone sequence
        if rho[t + 1] + rho[t + 2] > rho[t - 1] + rho[t]:
            rho[t + 1] = (rho[t - 1] + rho[t]) / 2.0
            rho[t + 2] = rho[t + 1]
        t += 2
    tau = -1.0 + 2.0 * np.sum(rho[: max_t + 1]) + np.sum(rho[max_t + 1: max_t + 2])
    tau = max(tau, 1 / np.log10(size))
    return float("nan") if np.isnan(rho).any() else size / tau


def _effective_draws(z: np.ndarray) -> np.ndarray:
    """Effective sample size of every parameter of z (p, m, n), chains as given (ArviZ's ``_ess``; z already
    split, finite)."""
    out = np.empty(z.shape[0])
    m, n = z.shape[1:]
    acov = _autocov(z)                                      # (p, m, n)
    mean_var = acov[:, :, 0].mean(axis=1) * n / (n - 1.0)
    var_plus = mean_var * (n - 1.0) / n
    if m > 1:
        var_plus = var_plus + np.var(z.mean(axis=2), axis=1, ddof=1)
    mean_acov = acov.mean(axis=1)
    flat = z.reshape(z.shape[0], -1)
    constant = flat.max(axis=1) - flat.min(axis=1) < np.finfo(float).resolution
    for j in range(z.shape[0]):
        out[j] = m * n if constant[j] else _geyer_effective_draws(mean_acov[j], var_plus[j], mean_var[j], m * n)
    return out


def ess(x: np.ndarray, method: str = "bulk", layout: str = "chains") -> np.ndarray:
    """Bulk effective sample size (rank-normalised split chains) of every parameter (``az.ess(method="bulk")``).

    Parameters
    ----------
    x : array
        (p, n_chains, n_draws), or an ensemble chain (n_ensembles, n_steps, n_walkers, dim) with
        ``layout="walkers"`` (every walker a chain, as the sampler's stopping rule) or ``"ensembles"``.
    method : str
        ``"bulk"`` (the only one).
    layout : str
        What a chain is (:data:`LAYOUTS`).

    Returns
    -------
    (p,) or (dim,) array
        ESS in draws; NaN where a parameter has non-finite draws or fewer than 4 draws.
    """
    if method != "bulk":
        raise ValueError(f"ESS method {method!r}: only 'bulk' is implemented")
    x = _as_chains(x, layout)
    out = np.full(x.shape[0], np.nan)
    ok = _valid(x, 1)
    if ok.any():
        out[ok] = _effective_draws(_z_scale(_split(x[ok])))
    return out


#: the columns of :func:`summary_diagnostics`, in ``az.summary(kind="diagnostics")``'s order
SUMMARY_COLUMNS = ("mcse_mean", "mcse_sd", "ess_bulk", "ess_tail", "r_hat")


def summary_diagnostics(x: np.ndarray) -> dict[str, np.ndarray]:
    """``az.summary(kind="diagnostics")`` of every parameter at once (ArviZ 0.23's ``_multichain_statistics``).

    With S = m·n draws of a parameter, x̄ their mean and s² = Σ(x − x̄)²/(S − 1):

        mcse_mean = √(s² / ESS_mean)                     ESS_mean: ESS of the split chains
        mcse_sd   = √(Var̂((x − x̄)²) / ESS_c2 / E[(x − x̄)²] / 4)   ESS_c2: of the split (x − x̄)²
        ess_bulk  = ESS of the rank-normalised split chains
        ess_tail  = min over q ∈ {5 %, 95 %} of the ESS of the split indicators 1{x ≤ quantile_q}
        r_hat     = max(R̂(z of the split chains), R̂(z of the split |x − median(x)|))   (median of all draws)

    Parameters
    ----------
    x : (p, n_chains, n_draws) array

    Returns
    -------
    dict
        :data:`SUMMARY_COLUMNS` → (p,) arrays; NaN where a parameter has non-finite draws or fewer than
        4 draws, ``r_hat`` also NaN with one chain (as ArviZ).
    """
    p = x.shape[0]
    out = {c: np.full(p, np.nan) for c in SUMMARY_COLUMNS}
    ok = _valid(x, 1)
    if not ok.any():
        return out
    y = x[ok]
    flat = y.reshape(y.shape[0], -1)
    size = flat.shape[1]
    split = _split(y)
    z_split = _z_scale(split)
    lo, hi = np.quantile(flat, [0.05, 0.95], axis=1)           # type 7, as ArviZ's mquantiles(1, 1)
    out["ess_tail"][ok] = np.minimum(_effective_draws(_split((y <= lo[:, None, None]).astype(float))),
                                     _effective_draws(_split((y <= hi[:, None, None]).astype(float))))
    if y.shape[1] >= 2:
        folded = np.abs(y - np.median(flat, axis=1)[:, None, None])
        out["r_hat"][ok] = np.maximum(_psrf(z_split), _psrf(_z_scale(_split(folded))))
    c2 = (y - flat.mean(axis=1)[:, None, None]) ** 2
    c2_sum = c2.reshape(c2.shape[0], -1).sum(axis=1)
    out["mcse_mean"][ok] = np.sqrt(c2_sum / (size - 1) / _effective_draws(split))
    evar = c2_sum / size
    varvar = ((c2 ** 2).reshape(c2.shape[0], -1).mean(axis=1) - evar ** 2) / _effective_draws(_split(c2))
    out["mcse_sd"][ok] = np.sqrt(varvar / evar / 4)
    out["ess_bulk"][ok] = _effective_draws(z_split)
    return out
