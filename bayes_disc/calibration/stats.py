"""Simulation-based calibration statistics (Talts, Betancourt, Simpson, Vehtari & Gelman 2018).

For a truth θ̃ drawn from the prior, data ỹ ~ p(y | θ̃) and L posterior draws θ_1…θ_L ~ p(θ | ỹ) that are
(close to) independent, the rank r = #{l : θ_l < θ̃} is uniform on {0, …, L} when the inference is
calibrated. Over N replicates the ranks are binned into B equal bins of (L + 1)/B ranks each and their
uniformity tested by Pearson's chi-square: X² = Σ_b (O_b − N/B)² / (N/B) ~ χ²_{B−1} under uniformity,
``rank_uniformity_p`` = P(χ²_{B−1} ≥ X²).

Coverage: the central 100·c % interval of the posterior draws [q_{(1−c)/2}, q_{(1+c)/2}] covers θ̃ in a
fraction of the replicates; calibrated inference covers with probability c, so over N replicates the count
is Binomial(N, c) and its central 95 % range (:func:`binomial_band`) is where an honest coverage falls.

Many coverages at once: a campaign counts K = (coefficients × levels) coverages, and each falls outside its
own 95 % band with probability α_k ≤ 0.05 (the band's exact outside mass, :func:`outside_probability`) even
for calibrated intervals — for K = 20 about one of them is expected outside (Σ α_k), and all 20 inside only
with probability ≈ Π (1 − α_k). The family-wise band (:func:`familywise_mass`, Bonferroni) is the central
range of mass 1 − 0.05/K: calibrated intervals put every one of the K coverages inside it with probability
≥ 95 %. Both are reported; a coverage outside its own band but inside the family-wise one is what chance
gives about once per campaign, one outside the family-wise band is evidence against calibration.

Posterior draws of MCMC are autocorrelated: :func:`thinned_draws` keeps every ⌈τ⌉-th step of every chain
(τ: integrated autocorrelation time in steps) before choosing the L draws, so that they are close to
independent; otherwise the rank histogram is ∪-shaped even for a correct posterior.

Width: the standardised error z = (θ̃ − posterior mean) / posterior sd has sd 1 over the replicates when the
intervals have the right width (exactly so for Gaussian posteriors, near it otherwise); ``z_sd`` > 1 says
too narrow, < 1 too wide. Its standard error ≈ 1/√(2(N − 1)) makes it a sharper test of the width than the
coverage counts (N = 100: ± 0.07 against a 50 % coverage band of ± 0.10).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

#: nominal masses of the central intervals whose coverage is counted
LEVELS = (0.5, 0.9)
#: probability mass of the binomial bands drawn around nominal coverage and the uniform rank count
BAND_MASS = 0.95


def sbc_rank(truth: float, draws: np.ndarray) -> int:
    """Rank of the truth among posterior draws, r = #{l : θ_l < θ̃} ∈ {0, …, L}.

    Parameters
    ----------
    truth : float
        θ̃, the value the data were made with.
    draws : ndarray, shape (L,)
        Posterior draws of the same quantity.

    Returns
    -------
    int
    """
    return int(np.count_nonzero(np.asarray(draws, float) < truth))


def covers(truth: float, draws: np.ndarray, level: float) -> bool:
    """Whether the central ``level`` interval of the draws contains the truth.

    Parameters
    ----------
    truth : float
        θ̃.
    draws : ndarray, shape (n,)
        Posterior draws.
    level : float
        Interval mass c ∈ (0, 1): the interval is [q_{(1−c)/2}, q_{(1+c)/2}] of the draws.

    Returns
    -------
    bool
    """
    lo, hi = np.quantile(np.asarray(draws, float), [(1 - level) / 2, (1 + level) / 2])
    return bool(lo <= truth <= hi)


def thinned_draws(chains: np.ndarray, tau: float, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """``n_draws`` nearly independent draws from MCMC chains: every ⌈τ⌉-th step, then a random subset.

    Parameters
    ----------
    chains : ndarray, shape (n_chains, n_steps, ...)
        Post-burn-in samples (every walker a chain); trailing axes are kept (e.g. parameters).
    tau : float
        Integrated autocorrelation time [steps] (the largest over the parameters).
    n_draws : int
        L, the number of draws wanted.
    rng : numpy.random.Generator
        Chooses the subset (without replacement).

    Returns
    -------
    ndarray, shape (n_draws, ...)

    Raises
    ------
    ValueError
        If the thinned chains hold fewer than ``n_draws`` draws.
    """
    chains = np.asarray(chains)
    step = max(1, int(math.ceil(tau))) if np.isfinite(tau) else chains.shape[1]
    kept = chains[:, ::step].reshape(-1, *chains.shape[2:])
    if len(kept) < n_draws:
        raise ValueError(f"only {len(kept)} draws after thinning every {step} steps; {n_draws} wanted")
    return kept[np.sort(rng.choice(len(kept), size=n_draws, replace=False))]


def rank_bins(n_draws: int, n_replicates: int, bins: int | None = None) -> int:
    """Number of rank-histogram bins B: a divisor of L + 1 with ≥ 5 replicates expected per bin.

    Parameters
    ----------
    n_draws : int
        L (ranks take L + 1 values).
    n_replicates : int
        N.
    bins : int, optional
        Wanted B (must divide L + 1); default the largest divisor of L + 1 that is ≤ 20 and ≤ N/5 (at least 2).

    Returns
    -------
    int
    """
    if bins is not None:
        if (n_draws + 1) % bins:
            raise ValueError(f"{bins} bins do not divide the {n_draws + 1} possible ranks")
        return bins
    cap = max(2, min(20, n_replicates // 5))
    return max([b for b in range(2, cap + 1) if (n_draws + 1) % b == 0] or [1])


def rank_counts(ranks: np.ndarray, n_draws: int, bins: int) -> np.ndarray:
    """Counts of ranks in ``bins`` equal bins of (L + 1)/B ranks each.

    Parameters
    ----------
    ranks : ndarray of int, shape (N,)
        Ranks in {0, …, L}.
    n_draws : int
        L.
    bins : int
        B, a divisor of L + 1.

    Returns
    -------
    ndarray of int, shape (B,)
    """
    ranks = np.asarray(ranks, int)
    if ranks.size and (ranks.min() < 0 or ranks.max() > n_draws):
        raise ValueError(f"ranks must lie in 0…{n_draws}")
    return np.bincount(ranks * bins // (n_draws + 1), minlength=bins)


def rank_uniformity_p(counts: np.ndarray) -> float:
    """Pearson chi-square p-value of binned ranks against the uniform distribution (module docstring).

    Parameters
    ----------
    counts : ndarray of int, shape (B,)
        Ranks per bin.

    Returns
    -------
    float
        P(χ²_{B−1} ≥ X²); NaN without replicates.
    """
    counts = np.asarray(counts, float)
    if counts.sum() == 0:
        return float("nan")
    return float(stats.chisquare(counts).pvalue)


def binomial_band(n: int, p: float, mass: float = BAND_MASS) -> tuple[float, float]:
    """Central ``mass`` range of a Binomial(n, p) count, as fractions of n.

    Parameters
    ----------
    n : int
        Trials (replicates).
    p : float
        Success probability (nominal coverage, or 1/B for a rank bin).
    mass : float
        Probability mass of the range.

    Returns
    -------
    (low, high) : tuple of float
        ``binom.ppf((1 − mass)/2, n, p) / n`` and ``binom.ppf((1 + mass)/2, n, p) / n``.
    """
    if n == 0:
        return float("nan"), float("nan")
    lo, hi = stats.binom.ppf([(1 - mass) / 2, (1 + mass) / 2], n, p)
    return float(lo / n), float(hi / n)


def outside_probability(n: int, p: float, mass: float = BAND_MASS) -> float:
    """Probability that a Binomial(n, p) count falls outside its central ``mass`` range (:func:`binomial_band`):
    ≤ 1 − ``mass`` (the range is discrete, so usually less); NaN for n = 0.

    Parameters
    ----------
    n : int
        Trials (replicates).
    p : float
        Success probability (nominal coverage).
    mass : float
        Probability mass of the range.

    Returns
    -------
    float
    """
    if n == 0:
        return float("nan")
    lo, hi = binomial_band(n, p, mass)
    inside = stats.binom.cdf(round(hi * n), n, p) - stats.binom.cdf(round(lo * n) - 1, n, p)
    return float(1.0 - inside)


def familywise_mass(k: int, mass: float = BAND_MASS) -> float:
    """Per-coverage mass 1 − (1 − ``mass``)/k of the Bonferroni band: k calibrated coverages all fall inside
    their bands with probability ≥ ``mass``."""
    return 1.0 - (1.0 - mass) / max(k, 1)


def z_sd(records: list[dict], name: str) -> float:
    """sd over the replicates (ddof 1) of z = (θ̃ − posterior mean) / posterior sd of coefficient ``name``
    (records with ``truth`` and ``posterior`` {name: {"mean", "sd"}}); NaN for fewer than 2."""
    z = [(r["truth"][name] - r["posterior"][name]["mean"]) / r["posterior"][name]["sd"] for r in records]
    return float(np.std(z, ddof=1)) if len(z) > 1 else float("nan")


def summarize(records: list[dict], names: list[str], n_draws: int, bins: int | None = None) -> dict:
    """``calibration.json`` content from the replicate records.

    Parameters
    ----------
    records : list of dict
        Successful replicates, each with ``ranks`` {name: r}, ``covered`` {"50"|"90": {name: bool}}, and
        ``truth`` and ``posterior`` {name: {"mean", "sd"}} (for ``z_sd``).
    names : list of str
        Coefficients, in order.
    n_draws : int
        L of every record.
    bins : int, optional
        Rank-histogram bins B (default :func:`rank_bins`).

    Returns
    -------
    dict
        ``replicates`` N and per coefficient ``coverage_50``, ``coverage_90``, ``rank_uniformity_p``,
        ``rank_counts`` (B,), ``z_sd`` (:func:`z_sd`), and the campaign-wide ``z_sd_se`` 1/√(2(N − 1)),
        ``rank_bins``, ``draws_per_replicate``, ``coverage_band_95`` {level: [low, high]},
        ``coverage_band_familywise_95`` {level: [low, high]} (mass :func:`familywise_mass` of K = len(names) ×
        len(LEVELS)), ``coverage_outside_expected`` (Σ over the K coverages of :func:`outside_probability`:
        how many calibrated intervals put outside their own 95 % band on average) and
        ``rank_count_band_95`` [low, high] (count per bin).
    """
    n = len(records)
    b = rank_bins(n_draws, n, bins)
    k = len(names) * len(LEVELS)
    coefficients = {}
    for name in names:
        ranks = np.array([r["ranks"][name] for r in records], int)
        counts = rank_counts(ranks, n_draws, b)
        entry = {f"coverage_{int(100 * lv)}": (float(np.mean([r["covered"][str(int(100 * lv))][name]
                                                               for r in records])) if n else float("nan"))
                 for lv in LEVELS}
        entry["rank_uniformity_p"] = rank_uniformity_p(counts)
        entry["rank_counts"] = counts.tolist()
        entry["z_sd"] = z_sd(records, name)
        coefficients[name] = entry
    lo, hi = binomial_band(n, 1.0 / b)
    return {"replicates": n, "coefficients": coefficients, "rank_bins": b, "draws_per_replicate": n_draws,
            "coverage_band_95": {str(int(100 * lv)): list(binomial_band(n, lv)) for lv in LEVELS},
            "coverage_band_familywise_95": {str(int(100 * lv)): list(binomial_band(n, lv, familywise_mass(k)))
                                            for lv in LEVELS},
            "coverage_outside_expected": len(names) * sum(outside_probability(n, lv) for lv in LEVELS),
            "rank_count_band_95": [lo * n, hi * n],
            "z_sd_se": 1.0 / math.sqrt(2 * (n - 1)) if n > 1 else float("nan")}
