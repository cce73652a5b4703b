"""Calibration of the likelihood alone, over many data sets: a linearised SBC at the truth.

A calibration campaign (``bayes-disc calibrate``) runs the sampler on every replicate and costs minutes per
data set. This benchmark makes the same replicates' data (:func:`replicate_data`: replicate i's truth, launches
and noise come from its own stream) and, without a sampler, computes the exact posterior of the model
linearised at the truth θ̃: with J the whitened Jacobian at θ̃ (data rows, then the prior's rows) and r the
whitened residuals there (then the prior's standardised deviations),

    δ = −(JᵀJ)⁻¹ Jᵀ r,        C = (JᵀJ)⁻¹,        z_j = −δ_j / √C_jj,        Q = δᵀ (JᵀJ) δ.

When the data come from the model's own noise law and the truth from the prior, z_j ~ N(0, 1) and
Q ~ χ²_dim exactly in the linear model: sd(z) and mean Q test the noise model and the synthesis against each
other over hundreds of data sets in minutes (0.2–0.4 s per data set); the campaign's sampler is not involved.
σ of each flight is its residuals' RMS at the truth.

``--rho held`` fixes every flight's AR(1) coefficient at the truth (its columns out of J); ``free`` (the
default) estimates it with the rest in the same Gauss–Newton step (J's ρ columns, ∂(W(ρ) r)/∂ρ, contain the
noise itself: the model is bilinear in ρ and θ, and one linear step is not its posterior); ``integrated``
computes the exact posterior of the model linear in θ with every flight's ρ_f integrated out:
given ρ the posterior of θ is Gaussian, N(m(ρ), C(ρ)) from the whitened raw Jacobian W(ρ) J₀/σ, and ρ is
integrated by adaptive importance sampling with weights p(y | ρ) p(ρ) / q(ρ), where

    log p(y | ρ) = log|W(ρ)| − n log σ(ρ) − ½ min_δ (|W(ρ)(r₀ + J₀ δ)/σ(ρ)|² + |(θ̃ + δ − μ)/s|²)
                   − ½ log det A(ρ) + const;

held at its true value is each flight's innovation sd τ_f = σ_f √(1 − ρ_f²), not σ_f: the data fix τ_f to
~2 %, so holding it agrees to first order with the sampler, which integrates σ_f under a Jeffreys prior (given
ρ, a Jeffreys prior on σ_f is one on τ_f), whereas a known σ_f would pin ρ_f through the stationary variance
σ_f² (a posterior sd of ρ 0.007 instead of the 0.017 a run with σ free reports);
the coefficients' posterior mean and sd are the mixture's. ``--fit`` instead minimises from the truth (nonlinear least squares with
the flights' σ re-estimated, as ``least_squares.json``) and standardises with the Laplace covariance there.
Where the campaign has a record of the replicate, its posterior z = (θ̃ − mean)/sd is compared.

    python benchmarks/bench_linear_sbc.py runs/calibration/four_flights_ar1.yaml [--first 0] [--replicates 300]
                                          [--rho free|held|integrated] [--fit] [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import binom

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration.config import load_cal_config  # noqa: E402
from bayes_disc.calibration.replicate import replicate_problem  # noqa: E402
from bayes_disc.calibration.stats import LEVELS  # noqa: E402
from bayes_disc.inference.fitting.residuals import _steps, jacobian_blocks, whitened_residuals
from bayes_disc.inference.fitting.leastsq import refine_least_squares, _rms  # noqa: E402
from bayes_disc.inference.model.truth import truth_theta  # noqa: E402


def at_truth(problem, theta: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(δ (n_free,), C (n_free, n_free), Q) of the Gauss–Newton step from the truth (module docstring)."""
    sigma = _rms(problem, theta)
    J = jacobian_blocks(theta, problem, sigma, free).dense()
    n_data = J.shape[0] - int(free.sum())
    r = whitened_residuals(theta, problem, sigma)
    r = np.r_[r[:n_data], r[n_data:][free]]
    A = J.T @ J
    C = np.linalg.inv(A)
    delta = -C @ (J.T @ r)
    return delta, C, float(delta @ A @ delta)


def raw_linearisation(problem, theta: np.ndarray, cols: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(r₀ (n_k,), J₀ (n_k, len(cols))) of flight k's marker channel at θ: the raw residuals (prediction −
    data) [m] and their central-difference Jacobian over the θ columns ``cols``.

    Raises
    ------
    SystemExit
        If flight k has other channels than its markers, or a simulation failed.
    """
    if len(problem.channels[k]) != 1:
        raise SystemExit(f"flight {problem.flights[k].name!r}: --rho integrated handles marker-only flights")
    h = _steps(problem, theta)[cols]
    lanes = np.repeat(theta[None], 2 * cols.size + 1, axis=0)
    lanes[np.arange(cols.size), cols] += h
    lanes[cols.size + np.arange(cols.size), cols] -= h
    [(c, pred)], ok = problem.channel_predictions(lanes, k)
    if not np.all(ok):
        raise SystemExit(f"flight {problem.flights[k].name!r}: a simulation near the truth failed")
    r = c.residuals(pred)
    return r[-1], ((r[: cols.size] - r[cols.size: 2 * cols.size]) / (2 * h)[:, None]).T


def rho_integrated(problem, theta: np.ndarray, tau: np.ndarray, rng: np.random.Generator,
                   draws: tuple[int, int] = (150, 300)) -> tuple[np.ndarray, np.ndarray, dict]:
    """Posterior mean and sd (dim,) (ρ entries: their posterior moments) of the model linear in θ at ``theta``
    with the flights' AR(1) ρ integrated out (module docstring); τ_f = ``tau`` (n_flights,) [m] the
    innovation sds, σ_f = τ_f / √(1 − ρ_f²).
    Adaptive importance sampling in ρ: a first stage from N(θ̃_ρ, 0.03²), a second from the first's
    moments (sd × 1.3); returns the second stage's moments and its effective sample size."""
    names = problem.names
    rho_idx = np.array([names.index(f"rho_{f.name}") for f in problem.flights])
    keep = np.setdiff1d(np.arange(problem.dim), rho_idx)          # θ without ρ
    pos = {j: i for i, j in enumerate(keep)}
    lin = []
    for k in range(problem.n_flights):
        cols = np.array([j for j in problem.flight_columns(k) if j in pos])
        r0, J0 = raw_linearisation(problem, theta, cols, k)
        lin.append((problem.channels[k][0], r0, J0, np.array([pos[j] for j in cols])))
    P = 1.0 / problem.prior_sd[keep] ** 2
    d0 = (theta[keep] - problem.prior_mean[keep]) * P              # P (θ̃ − μ)

    def conditional(rho: np.ndarray):
        A = np.diag(P)
        b = d0.copy()
        logw, pieces = 0.0, []
        for k, (c, r0, J0, at) in enumerate(lin):
            own = np.array([[rho[k]]])
            sigma = tau[k] / np.sqrt(1.0 - rho[k] ** 2)
            w0 = c.noise.whiten(r0[None], own)[0] / sigma
            Jw = c.noise.whiten(np.ascontiguousarray(J0.T), np.repeat(own, J0.shape[1], 0)).T / sigma
            A[np.ix_(at, at)] += Jw.T @ Jw
            b[at] += Jw.T @ w0
            logw += float(c.noise.log_det(own)[0]) - r0.size * np.log(sigma)
            pieces.append((w0, Jw, at))
        L = np.linalg.cholesky(A)
        delta = -np.linalg.solve(A, b)
        mis = sum(float(np.sum((w0 + Jw @ delta[at]) ** 2)) for w0, Jw, at in pieces)
        mis += float(np.sum(P * (theta[keep] + delta - problem.prior_mean[keep]) ** 2))
        logp = logw - 0.5 * mis - float(np.sum(np.log(np.diag(L))))
        logp += float(np.sum(-0.5 * ((rho - problem.prior_mean[rho_idx]) / problem.prior_sd[rho_idx]) ** 2))
        return logp, theta[keep] + delta, np.linalg.inv(A)

    centre, spread = theta[rho_idx].copy(), np.full(rho_idx.size, 0.03)
    for n in draws:
        rho = centre + spread * rng.standard_normal((n, rho_idx.size))
        rho = rho[np.all(np.abs(rho) < 1.0, axis=1)]
        out = [conditional(r) for r in rho]
        lq = -0.5 * np.sum(((rho - centre) / spread) ** 2, axis=1)
        lw = np.array([o[0] for o in out]) - lq
        w = np.exp(lw - lw.max())
        w /= w.sum()
        centre = w @ rho
        rsd = np.sqrt(w @ (rho - centre) ** 2)
        spread = 1.3 * rsd
    m = np.array([o[1] for o in out])
    var = np.array([np.diag(o[2]) for o in out])
    mean = w @ m
    sd_keep = np.sqrt(w @ var + w @ (m - mean) ** 2)
    full_mean, full_sd = theta.copy(), np.zeros(problem.dim)
    full_mean[keep], full_sd[keep] = mean, sd_keep
    full_mean[rho_idx], full_sd[rho_idx] = centre, rsd
    return full_mean, full_sd, {"ess": float(1.0 / np.sum(w ** 2)), "draws": int(w.size)}


def replicate_z(cal, index: int, names, rho: str, fit: bool) -> dict:
    problem, _, result, _ = replicate_problem(cal, index)
    truth = result.truth
    theta = truth_theta(problem, truth)
    idx = [problem.names.index(n) for n in names]
    if rho == "integrated":
        if not any(n.startswith("rho_") for n in problem.names):
            raise SystemExit(f"--rho integrated: {cal.path} does not fit AR(1) noise (run.noise.model ar1)")
        rho_true = theta[[problem.names.index(f"rho_{f.name}") for f in problem.flights]]
        tau = np.array([truth["flights"][f.name]["noise_m"] for f in problem.flights]) * np.sqrt(1 - rho_true ** 2)
        mean, sd, info = rho_integrated(problem, theta, tau, np.random.default_rng([index, 28]))
        rho_idx = [i for i, n in enumerate(problem.names) if n.startswith("rho_")]
        return {"index": index, "dim": None, "Q": None, "has_rho": True, "z": [float((theta[i] - mean[i]) / sd[i]) for i in idx],
                "rho_mean": mean[rho_idx].tolist(), "rho_sd": sd[rho_idx].tolist(), **info}
    held = np.array([rho == "held" and n.startswith("rho_") for n in problem.names])
    free = ~held
    out = {"index": index, "dim": int(free.sum()), "Q": None, "has_rho": any(n.startswith("rho_") for n in problem.names)}
    if fit:                                                  # the least-squares optimum instead of the linear step
        ls = refine_least_squares(problem, theta, max_nfev=60, free=free)
        sd = np.sqrt(np.diag(ls.cov))
        out["z"] = [float((theta[i] - ls.theta[i]) / sd[i]) for i in idx]
        out["rho_hat"] = [float(v) for n, v in zip(problem.names, ls.theta) if n.startswith("rho_")]
        return out
    cols = np.cumsum(free) - 1                               # θ index -> free index
    delta, C, out["Q"] = at_truth(problem, theta, free)
    out["z"] = [float(-delta[cols[i]] / np.sqrt(C[cols[i], cols[i]])) for i in idx]
    return out


def campaign_z(cal, index: int, names) -> list | None:
    f = cal.output / "replicates" / f"replicate_{index:05d}.json"
    if not f.exists():
        return None
    rec = json.loads(f.read_text())
    if rec.get("status") != "ok":
        return None
    return [(rec["truth"][n] - rec["posterior"][n]["mean"]) / rec["posterior"][n]["sd"] for n in names]


def coverage(z: np.ndarray) -> dict:
    """Central-interval coverage per level (fraction of |z| inside the normal quantile) and its 95 % band."""
    from scipy.stats import norm
    n = z.shape[0]
    return {str(int(100 * lv)): {"coverage": (np.abs(z) < norm.ppf(0.5 + lv / 2)).mean(0).tolist(),
                                 "band": (binom.ppf([0.025, 0.975], n, lv) / n).tolist()} for lv in LEVELS}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--replicates", type=int, default=300)
    ap.add_argument("--rho", choices=("free", "held", "integrated"), default="free",
                    help="AR(1) coefficients estimated in the linear step (free), held at the truth, or integrated out")
    ap.add_argument("--fit", action="store_true", help="least squares from the truth instead of one linear step")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if a.fit and a.rho == "integrated":
        ap.error("--fit and --rho integrated exclude each other")
    cal = load_cal_config(a.campaign)
    names = list(cal.names)
    rows, t0 = [], time.perf_counter()
    for i in range(a.first, a.first + a.replicates):
        rows.append(replicate_z(cal, i, names, a.rho, a.fit))
        rows[-1]["campaign_z"] = campaign_z(cal, i, names)
        if (len(rows)) % 25 == 0:
            print(f"{len(rows)}/{a.replicates} replicates, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    z = np.array([r["z"] for r in rows])
    n = len(rows)
    linear = a.rho != "integrated" and not a.fit           # Q is the linear step's
    dims = np.array([r["dim"] for r in rows]) if linear else np.zeros(1)
    Q = np.array([r["Q"] for r in rows]) if linear else np.zeros(1)
    paired = [(r["z"], r["campaign_z"]) for r in rows if r["campaign_z"] is not None]
    out = {"campaign": str(a.campaign), "replicates": n, "first": a.first, "rho": a.rho, "fit": a.fit,
           "seconds_per_replicate": (time.perf_counter() - t0) / n,
           "sd_z": dict(zip(names, z.std(0, ddof=1).tolist())), "sd_z_se": 1 / np.sqrt(2 * (n - 1)),
           "coverage": {lv: dict(v, names=names) for lv, v in coverage(z).items()},
           **({"Q_mean": float(Q.mean()), "dim_mean": float(dims.mean()), "Q_mean_se": float(np.sqrt(2 * dims.mean() / n))}
              if linear else {} if a.fit else {"rho_posterior_mean": float(np.mean([r["rho_mean"] for r in rows])),
                              "rho_posterior_sd": float(np.mean([r["rho_sd"] for r in rows])),
                              "min_ess": float(min(r["ess"] for r in rows))})}
    if a.fit:
        rh = np.concatenate([r["rho_hat"] for r in rows]) if rows[0]["rho_hat"] else np.zeros(0)
        out["rho_hat"] = {"mean": float(rh.mean()), "median": float(np.median(rh)), "n": int(rh.size)} if rh.size else None
    if paired:
        zl, zc = (np.array(v) for v in zip(*paired))
        out["campaign_records"] = {"replicates": len(paired), "sd_z_here": dict(zip(names, zl.std(0, ddof=1).tolist())),
                           "sd_z_campaign": dict(zip(names, zc.std(0, ddof=1).tolist())),
                           "correlation": {nm: float(np.corrcoef(zl[:, j], zc[:, j])[0, 1]) for j, nm in enumerate(names)}}
    if a.json:
        print(json.dumps(out, indent=1))
        return 0
    how = ("least squares from the truth" if a.fit else "one Gauss–Newton step from the truth" if linear
           else "the posterior linear in θ at the truth, ρ integrated")
    rho = f", AR(1) ρ {a.rho}" if rows[0]["has_rho"] else ""
    print(f"{n} replicates ({a.first}–{a.first + n - 1}) of {a.campaign}: {how}{rho}; "
          f"{out['seconds_per_replicate']:.2f} s each")
    if linear:
        print(f"mean Q {out['Q_mean']:.2f} for χ²_{out['dim_mean']:.0f} (se {out['Q_mean_se']:.2f})")
    else:
        print(f"ρ posterior: mean {out['rho_posterior_mean']:.4f}, sd {out['rho_posterior_sd']:.4f} (averages over "
              f"flights and replicates); smallest importance-sampling ESS {out['min_ess']:.0f}")
    c50, c90 = out["coverage"]["50"], out["coverage"]["90"]
    print(f"{'':6s} {'sd z':>6s} {'50 %':>6s} {'90 %':>6s}   (se of sd {out['sd_z_se']:.3f}; bands "
          f"{c50['band'][0]:.2f}–{c50['band'][1]:.2f}, {c90['band'][0]:.2f}–{c90['band'][1]:.2f})")
    for j, nm in enumerate(names):
        print(f"{nm:6s} {out['sd_z'][nm]:6.3f} {c50['coverage'][j]:6.2f} {c90['coverage'][j]:6.2f}")
    if a.fit and out.get("rho_hat"):
        print(f"AR(1) ρ̂: mean {out['rho_hat']['mean']:.4f}, median {out['rho_hat']['median']:.4f} over {out['rho_hat']['n']} flights")
    if paired:
        c = out["campaign_records"]
        print(f"campaign records for {c['replicates']} of these: sd z here / campaign, correlation")
        for nm in names:
            print(f"{nm:6s} {c['sd_z_here'][nm]:6.3f} {c['sd_z_campaign'][nm]:6.3f} {c['correlation'][nm]:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
