"""Metropolis–Hastings proposals of the sampler, each with an exact density (so every move's acceptance
ratio is exact and the posterior stays invariant whatever the proposal's quality).

* :class:`Proposal` — a Gaussian reference N(μ, Σ), re-fitted to the warm-up samples: the shape of the
  sampler's flight-block moves (:mod:`.moves`).
* :class:`MixtureProposal` — a Gaussian mixture (here: the Laplace approximation at the optimum).
* :class:`RidgeProposal` — follows a profile-likelihood path (:mod:`.profile`) of one parameter θ_i:
  θ_i from the Laplace marginal along the path, g(v) ∝ p(θ*(v) | y) |S(v)|^½ (interpolated log-linearly
  between path points), then θ_−i | θ_i = v from the conditional Gaussian of the local Gauss–Newton
  covariance Σ(v), mean θ*_−i(v) + b(v)(v − θ*_i) with b = Σ_−i,i / Σ_ii, covariance
  S = Σ_−i,−i − b Σ_i,−i (interpolated between path points). Where the posterior is a thin curved valley
  whose width grows along it (the demo's CM0–CMq–wobble combination: e^16 in volume along the CMq
  path), no single Gaussian, nor a mixture of full local Gaussians, covers it (independence jumps
  accepted ≤ 1 %); following the path with interpolated local conditionals does (≈ 24 %).
* :class:`CompositeProposal` — a weighted mixture of proposals: the independence proposal of the sampler
  is the Laplace approximation plus one ridge proposal per profile path that departs from it; its
  weights are re-fitted to the warm-up samples (where the posterior's mass lies away from the mode,
  the Laplace part and the ridges of well-determined parameters are hardly ever accepted).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy.linalg import solve_triangular

from ._ridge_kernels import interpolated_product, interpolated_whiten
from ..fitting.covariance import scaled_cholesky
from ..model.problem import Problem

#: proposal sd / posterior sd after a warm-up re-fit (slightly wider: safe tails)
PROPOSAL_INFLATION = 1.03


@dataclass(frozen=True)
class Proposal:
    """Gaussian reference N(μ, Σ), Σ = L Lᵀ: the moments of the independence proposal, then of the
    warm-up samples (:meth:`refit`); the flight-block moves take their shape from it (:mod:`.moves`).

    It once proposed preconditioned Crank–Nicolson steps x′ = μ + ρ (x − μ) + √(1 − ρ²) L z; on
    the curved posteriors here they were accepted < 1 % of the time (:mod:`.sampler`), so they were
    dropped."""

    mean: np.ndarray
    chol: np.ndarray
    adapted: int = 0   # how many warm-up re-fits this proposal has had

    @classmethod
    def from_cov(cls, mean, cov, adapted=0) -> "Proposal":
        return cls(mean=np.asarray(mean, float), chol=scaled_cholesky(0.5 * (cov + cov.T)), adapted=adapted)

    @property
    def cov(self) -> np.ndarray:
        """Σ = L Lᵀ (dim, dim)."""
        return self.chol @ self.chol.T

    def refit(self, samples: np.ndarray) -> "Proposal":
        """The reference re-fitted to samples (n, dim): their mean and inflated covariance."""
        cov = np.cov(samples.T) * PROPOSAL_INFLATION**2
        return Proposal.from_cov(samples.mean(axis=0), cov, self.adapted + 1)

    def log_density(self, x: np.ndarray) -> np.ndarray:
        """ln N(x) up to its constant, for x (n, dim)."""
        z = solve_triangular(self.chol, (x - self.mean).T, lower=True)
        return -0.5 * np.sum(z * z, axis=0)

    def draw(self, n: int, random) -> np.ndarray:
        return self.mean + random.randn(n, self.mean.size) @ self.chol.T

    def save(self, path: Path) -> None:
        np.savez(path, mean=self.mean, chol=self.chol, adapted=self.adapted)

    @classmethod
    def load(cls, path: Path) -> "Proposal":
        z = np.load(path)
        return cls(mean=z["mean"], chol=z["chol"], adapted=int(z["adapted"]))


@dataclass(frozen=True)
class MixtureProposal:
    """Gaussian mixture Σ_k w_k N(m_k, L_k L_kᵀ), used as an independence proposal (emcee MHMove):
    x′ ~ mixture, log factor ln q(x) − ln q(x′)."""

    means: np.ndarray        # (K, dim)
    chols: np.ndarray        # (K, dim, dim) lower-triangular
    log_weights: np.ndarray  # (K,) normalised

    @classmethod
    def from_components(cls, means, covs, log_weights) -> "MixtureProposal":
        lw = np.asarray(log_weights, float)
        lw = lw - np.logaddexp.reduce(lw)
        return cls(np.asarray(means, float), np.array([scaled_cholesky(c) for c in covs]), lw)

    @property
    def weights(self) -> np.ndarray:
        return np.exp(self.log_weights)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance of the mixture."""
        w = self.weights
        mean = w @ self.means
        dev = self.means - mean
        cov = np.einsum("k,kij,klj->il", w, self.chols, self.chols) + (dev.T * w) @ dev
        return mean, 0.5 * (cov + cov.T)

    @cached_property
    def _whitening(self):
        """(stacked L_k⁻¹ (K·dim, dim), L_k⁻¹ m_k (K, dim), ln w_k − ln|L_k| (K,))."""
        K, d = self.means.shape
        inv = np.array([solve_triangular(L, np.eye(d), lower=True) for L in self.chols])
        const = self.log_weights - np.log(np.diagonal(self.chols, axis1=1, axis2=2)).sum(axis=1)
        return inv.reshape(K * d, d), np.einsum("kij,kj->ki", inv, self.means), const

    def log_density(self, x: np.ndarray) -> np.ndarray:
        """ln q(x) for x (n, dim): all components' whitened offsets L_k⁻¹(x − m_k) in one matrix product."""
        x = np.atleast_2d(x)
        K, d = self.means.shape
        inv, shift, const = self._whitening
        z = (inv @ x.T).reshape(K, d, -1) - shift[:, :, None]
        out = const[:, None] - 0.5 * np.einsum("kdn,kdn->kn", z, z)
        return np.logaddexp.reduce(out, axis=0) - 0.5 * d * np.log(2 * np.pi)

    def draw(self, n: int, random) -> np.ndarray:
        """n (n, dim) draws: a component per draw, then m_k + L_k z, one matrix product per component (not
        a gathered (n, dim, dim) stack of factors: 2.8 GB for 4000 draws at 298 parameters)."""
        k = random.choice(self.means.shape[0], size=n, p=self.weights / self.weights.sum())
        z = random.randn(n, self.means.shape[1])
        out = self.means[k]
        for j in np.unique(k):
            at = k == j
            out[at] += z[at] @ self.chols[j].T
        return out

    def __call__(self, coords, random):
        new = self.draw(coords.shape[0], random)
        return new, self.log_density(coords) - self.log_density(new)

    def save(self, path: Path) -> None:
        np.savez(path, means=self.means, chols=self.chols, log_weights=self.log_weights)

    @classmethod
    def load(cls, path: Path) -> "MixtureProposal":
        z = np.load(path)
        return cls(means=z["means"], chols=z["chols"], log_weights=z["log_weights"])


#: a profile path whose deviance departs from t² by more than this (in units of 1 + t²/4), or whose
#: points lie farther than this from the Laplace prediction (Mahalanobis), gets a ridge proposal
PROFILE_DEPARTURE = 1.0
#: the Mahalanobis test looks at path points up to this profile deviance (3 σ)
DEPARTURE_DEVIANCE = 9.0
#: share of the central Laplace approximation in the independence proposal (the rest: ridge proposals),
#: before the weights are re-fitted to warm-up samples (:meth:`CompositeProposal.reweighted`)
CENTRAL_WEIGHT = 0.2
#: least weight of a part after re-fitting
WEIGHT_FLOOR = 0.02


def path_departure(path, theta_hat: np.ndarray, cov_hat: np.ndarray) -> float:
    """How far a profile path strays from what the Laplace approximation predicts: the larger of its
    deviance misfit (:meth:`.ProfilePath.gaussian_misfit`) and the Mahalanobis distance (Laplace metric)
    between each path point within ``DEPARTURE_DEVIANCE`` and the Laplace conditional mean
    θ̂ + Σ_:,i/Σ_ii · (v − θ̂_i)."""
    i = path.index
    L = scaled_cholesky(cov_hat)
    worst = path.gaussian_misfit()
    for p in path.points:
        if p.deviance > DEPARTURE_DEVIANCE:
            continue
        pred = theta_hat + cov_hat[:, i] / cov_hat[i, i] * (p.value - theta_hat[i])
        z = solve_triangular(L, p.theta - pred, lower=True)
        worst = max(worst, float(np.sqrt(z @ z)))
    return worst


@dataclass(frozen=True)
class RidgeProposal:
    """Independence proposal along the profile path of parameter ``index`` (see the module docstring).

    Path points k = 0 … K−1 (sorted by v_k = θ*_k,i) carry the Laplace-marginal log density
    ℓ_k = ln p(θ*_k | y) + ½ ln|S_k| (relative), the conditional mean θ*_k,−i with slope b_k and the
    Cholesky factor L_k of S_k. Between two points, ln g(v) is linear in v and the conditional is
    N(m(v), L(v) L(v)ᵀ): m the cubic Hermite interpolant of the points θ*_k,−i with tangents b_k
    (:meth:`_segment`), L(v) = (1−a) L_k + a L_k+1, a = (v − v_k)/(v_k+1 − v_k); beyond the end points g has
    Gaussian tails of the end points' local sd s and the conditional follows the end point's tangent line.
    The density is continuous and exact (normalised analytically).

    The factors may be block-sparse (``first``, ``shared``: :mod:`._ridge_kernels`): built for a run's
    problem, the flights' rows below the shared ones keep their own flight's block only, as the Laplace
    covariance of the arrow-structured precision has it (its other entries are rounding, ≤ 10⁻¹³ of the
    block's on seed 18's 24 flights), and the per-point algebra skips the zeros."""

    index: int
    v: np.ndarray            # (K,) path values of θ_i, increasing
    log_g: np.ndarray        # (K,) Laplace-marginal log density at the points (relative)
    s: np.ndarray            # (K,) local sd of θ_i (only the end points' are used: tails)
    means: np.ndarray        # (K, dim − 1) θ*_k,−i
    slopes: np.ndarray       # (K, dim − 1) b_k
    chols: np.ndarray        # (K, dim − 1, dim − 1) Cholesky factors of S_k
    first: np.ndarray | None = None   # (dim − 1,) first column of every row's own block; None: dense
    shared: int = 0                   # leading columns every row may use

    @classmethod
    def from_path(cls, problem: Problem, path, blocks=None) -> "RidgeProposal":
        """The ridge proposal of a profile path (:mod:`.profile`).

        Parameters
        ----------
        problem : Problem
        path : ProfilePath
        blocks : (int, sequence of slice), optional
            The parameters every block may depend on (the first ``blocks[0]`` of θ: the shared ones, which
            must include θ_i) and the blocks of θ that are independent given them (every flight's slice):
            the factors are then block-sparse (:func:`flight_blocks`). None: dense factors.
        """
        i = path.index
        first, shared = (None, 0) if blocks is None else _block_structure(i, problem.dim, *blocks)
        pts = sorted((p for p in path.points if p.ok), key=lambda p: p.value)
        lp = problem.log_prob(np.array([p.theta for p in pts])) if pts else np.zeros(0)
        rest = np.r_[0:i, i + 1:problem.dim]
        v, s, lg, means, slopes, chols = [], [], [], [], [], []
        for p, lpk in zip(pts, lp):
            if not np.isfinite(lpk) or (v and p.value <= v[-1]):
                continue
            S = p.cov
            b = S[rest, i] / S[i, i]
            L = scaled_cholesky(S[np.ix_(rest, rest)] - np.outer(b, S[i, rest]))
            if first is not None:
                L = L * _structure_mask(first, shared)
            v.append(p.value)
            s.append(np.sqrt(S[i, i]))
            lg.append(lpk + np.sum(np.log(np.diag(L))))
            means.append(p.theta[rest])
            slopes.append(b)
            chols.append(L)
        lg = np.array(lg)
        return cls(i, np.array(v), lg - lg.max() if lg.size else lg, np.array(s), np.array(means),
                   np.array(slopes), np.array(chols), first, shared)

    @property
    def _structure(self) -> tuple[np.ndarray, int]:
        """(first, shared) for the compiled loops: a dense factor is first = 0, shared = 0."""
        if self.first is None:
            return np.zeros(self.chols.shape[1], np.int64), 0
        return self.first, self.shared

    # -- the 1-D density g of θ_i -------------------------------------------------------------------------
    def _pieces(self):
        """Masses of: the left tail, each segment, the right tail (unnormalised); and segment slopes."""
        h = np.diff(self.v)
        beta = np.diff(self.log_g) / h
        bh = beta * h
        seg = np.exp(self.log_g[:-1]) * h * np.where(np.abs(bh) > 1e-12, np.expm1(bh) / np.where(bh == 0, 1, bh), 1.0)
        tails = np.exp(self.log_g[[0, -1]]) * self.s[[0, -1]] * np.sqrt(np.pi / 2)
        return np.r_[tails[0], seg, tails[1]], beta, h

    def log_g_density(self, x: np.ndarray) -> np.ndarray:
        mass, beta, h = self._pieces()
        out = np.interp(x, self.v, self.log_g)
        lo, hi = x < self.v[0], x > self.v[-1]
        out[lo] = self.log_g[0] - 0.5 * ((x[lo] - self.v[0]) / self.s[0]) ** 2
        out[hi] = self.log_g[-1] - 0.5 * ((x[hi] - self.v[-1]) / self.s[-1]) ** 2
        return out - np.log(mass.sum())

    def draw_g(self, n: int, random) -> np.ndarray:
        mass, beta, h = self._pieces()
        piece = random.choice(mass.size, size=n, p=mass / mass.sum())
        u = random.rand(n)
        x = np.empty(n)
        left, right = piece == 0, piece == mass.size - 1
        x[left] = self.v[0] - self.s[0] * np.abs(random.randn(int(left.sum())))
        x[right] = self.v[-1] + self.s[-1] * np.abs(random.randn(int(right.sum())))
        mid = ~(left | right)
        j = piece[mid] - 1
        bj, hj, uj = beta[j], h[j], u[mid]
        flat = np.abs(bj * hj) < 1e-12
        step = np.where(flat, uj * hj, np.log1p(uj * np.expm1(bj * hj)) / np.where(flat, 1.0, bj))
        x[mid] = self.v[j] + step
        return x

    # -- the conditional of the other parameters ---------------------------------------------------------
    def _segment(self, vi: np.ndarray):
        """For values vi (n,) of θ_i: the segment k (n,), the weight a of its right end and the conditional
        mean (n, dim − 1).

        The mean is the cubic Hermite interpolant of the path points θ*_k,−i with the slopes b_k as
        tangents (h = v_k+1 − v_k):

            mean(v) = h₀₀(a) θ*_k + h₁₀(a) h b_k + h₀₁(a) θ*_k+1 + h₁₁(a) h b_k+1,
            h₀₀ = 2a³ − 3a² + 1,  h₁₀ = a³ − 2a² + a,  h₀₁ = 3a² − 2a³,  h₁₁ = a³ − a²,

        exact where the valley's floor is a cubic in v; beyond the end points, the end points' tangent
        lines. A thin valley that bends (the real logger throws: the coefficients with the release speeds)
        leaves a linear blend of the tangent lines off its floor by c h² a (1 − a) for a floor c v², many
        times its width halfway between path points (there the log posterior lay 40–180 below its values at
        the path points; 1–3 with this interpolant)."""
        k = np.clip(np.searchsorted(self.v, vi) - 1, 0, self.v.size - 2)
        h = self.v[k + 1] - self.v[k]
        a = np.clip((vi - self.v[k]) / h, 0.0, 1.0)
        a2, a3 = a * a, a * a * a
        h00, h10, h01, h11 = 2 * a3 - 3 * a2 + 1, a3 - 2 * a2 + a, 3 * a2 - 2 * a3, a3 - a2
        below, above = np.minimum(vi - self.v[k], 0.0), np.maximum(vi - self.v[k + 1], 0.0)  # 0 inside the path
        mean = (h00[:, None] * self.means[k] + (h10 * h)[:, None] * self.slopes[k] + h01[:, None] * self.means[k + 1]
                + (h11 * h)[:, None] * self.slopes[k + 1] + below[:, None] * self.slopes[k]
                + above[:, None] * self.slopes[k + 1])
        return k, a, mean

    def whiten(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The conditional's whitened coordinates of points x (n, dim): z = L(x_i)⁻¹ (x_−i − mean(x_i)), every
        point's triangular system solved in one compiled pass (:func:`._ridge_kernels.interpolated_whiten`:
        the sampler does this for every walker at every independence jump).

        Returns
        -------
        z : (n, dim − 1) array
        log_det : (n,) array
            ln |L(x_i)|.
        """
        x = np.atleast_2d(x)
        k, a, mean = self._segment(x[:, self.index])
        return interpolated_whiten(self.chols, k, a, np.ascontiguousarray(np.delete(x, self.index, axis=1) - mean),
                                   *self._structure)

    def place(self, vi: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The inverse of :meth:`whiten`: points (n, dim) with θ_i = vi (n,) and θ_−i = mean(vi) + L(vi) z, z
        (n, dim − 1); also ln |L(vi)| (n,)."""
        k, a, mean = self._segment(vi)
        rest = mean + interpolated_product(self.chols, k, a, np.ascontiguousarray(z), *self._structure)
        diag = np.diagonal(self.chols, axis1=1, axis2=2)
        log_det = np.log((1 - a)[:, None] * diag[k] + a[:, None] * diag[k + 1]).sum(axis=1)
        return np.insert(rest, self.index, vi, axis=1), log_det

    def block_conditionals(self, x: np.ndarray, shared: int, blocks) -> list[tuple[np.ndarray, np.ndarray]]:
        """The ridge's conditional of each block of parameters given θ_i and the first ``shared`` other
        parameters, at points x (n, dim), from the lower-triangular factor alone: θ_b = m_b(v) + L_bs(v) z_s +
        L_bb(v) z_b with z_s = L_ss(v)⁻¹ (θ_s − m_s(v)). It is the ridge's exact conditional when the blocks are
        independent given θ_s (the flights given the shared parameters: the Laplace covariance of an arrow
        precision, whose factor is block-diagonal below the shared rows to rounding, 10⁻¹³ of its entries);
        as a proposal it is exact in any case.

        Parameters
        ----------
        x : (n, dim) array
        shared : int
            s, the parameters of θ_−i before the blocks (all indices below ``shared`` + 1 except i).
        blocks : sequence of slice
            Blocks of θ (indices ≥ s + 1), e.g. every flight's slice of the parameter layout.

        Returns
        -------
        list of (mean (n, p_b), chol (n, p_b, p_b)) per block
        """
        x = np.atleast_2d(x)
        k, a, mean = self._segment(x[:, self.index])
        rest = np.delete(x, self.index, axis=1)
        cols = np.arange(shared)

        def factor(rows, c):
            """L(v)[rows, c] of every point (n, len(rows), len(c))."""
            at = (rows[None, :, None], c[None, None, :])
            lo, hi = self.chols[(k[:, None, None],) + at], self.chols[(k[:, None, None] + 1,) + at]
            return (1 - a)[:, None, None] * lo + a[:, None, None] * hi

        z_s = np.linalg.solve(factor(cols, cols), (rest[:, :shared] - mean[:, :shared])[..., None])[..., 0]
        out = []
        for b in blocks:
            rows = np.arange(b.start, b.stop)
            rows = rows - (rows > self.index)
            out.append((mean[:, rows] + np.einsum("npq,nq->np", factor(rows, cols), z_s), factor(rows, rows)))
        return out

    def log_density(self, x: np.ndarray) -> np.ndarray:
        """ln q(x) for points x (n, dim): ln g(x_i) + ln N(x_−i; mean(x_i), L(x_i) L(x_i)ᵀ) (:meth:`whiten`)."""
        x = np.atleast_2d(x)
        z, log_det = self.whiten(x)
        return (self.log_g_density(x[:, self.index]) - 0.5 * z.shape[1] * np.log(2 * np.pi) - log_det
                - 0.5 * np.einsum("nd,nd->n", z, z))

    def draw(self, n: int, random) -> np.ndarray:
        vi = self.draw_g(n, random)
        return self.place(vi, random.randn(n, self.means.shape[1]))[0]

    def arrays(self) -> dict:
        out = {"index": np.array(self.index), "v": self.v, "log_g": self.log_g, "s": self.s,
               "means": self.means, "slopes": self.slopes, "chols": self.chols}
        if self.first is not None:
            out.update(first=self.first, shared=np.array(self.shared))
        return out


def flight_blocks(problem: Problem) -> tuple[int, list[slice]]:
    """The problem's arrow structure for :meth:`RidgeProposal.from_path`: the shared parameters' count and
    every flight's slice of θ."""
    return problem.ic_start, [problem.layout.flight_slice(k) for k in range(problem.n_flights)]


def _block_structure(i: int, dim: int, n_shared: int, slices) -> tuple[np.ndarray, int]:
    """``first`` and ``shared`` of a ridge along θ_i (rows and columns of θ_−i) for shared parameters
    θ_0 … θ_(n_shared − 1) and blocks ``slices`` of θ, all after them."""
    if not 0 <= i < n_shared:
        raise ValueError(f"ridge along parameter {i}: block-sparse factors need it among the {n_shared} shared ones")
    first = np.zeros(dim - 1, np.int64)
    for sl in slices:
        if sl.start < n_shared:
            raise ValueError(f"block {sl} overlaps the {n_shared} shared parameters")
        first[sl.start - 1:sl.stop - 1] = sl.start - 1
    return first, n_shared - 1


def _structure_mask(first: np.ndarray, shared: int) -> np.ndarray:
    """(d, d) bool: the entries a block-sparse factor keeps (:mod:`._ridge_kernels`)."""
    r = np.arange(first.size)[:, None]
    c = np.arange(first.size)[None, :]
    return (c < np.minimum(r, shared)) | ((c >= np.maximum(first[:, None], np.minimum(r, shared))) & (c <= r))


@dataclass(frozen=True)
class CompositeProposal:
    """Σ_j w_j q_j(x) over proposals with ``log_density`` and ``draw``; the sampler jumps from it with
    :class:`.moves.IndependenceJump`."""

    parts: tuple
    log_weights: np.ndarray

    def log_density(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        return np.logaddexp.reduce([lw + q.log_density(x) for lw, q in zip(self.log_weights, self.parts)], axis=0)

    def draw(self, n: int, random) -> np.ndarray:
        w = np.exp(self.log_weights)
        j = random.choice(len(self.parts), size=n, p=w / w.sum())
        out = np.empty((n, self.parts[0].draw(1, random).shape[1]))
        for jj in np.unique(j):
            out[j == jj] = self.parts[jj].draw(int(np.sum(j == jj)), random)
        return out

    def laplace_covariance(self) -> np.ndarray:
        """(dim, dim) covariance of the Laplace approximation, the first part (:func:`independence_proposal`)."""
        return self.parts[0].moments()[1]

    def reweighted(self, samples: np.ndarray, floor: float = WEIGHT_FLOOR) -> "CompositeProposal":
        """Weights re-fitted to posterior samples (n, dim) by one EM step: w_j ← mean over the samples of
        the part's responsibility w_j q_j(x) / q(x) (maximises E_π[ln q] over the weights), floored at
        ``floor`` so no part is switched off."""
        lq = np.array([lw + q.log_density(samples) for lw, q in zip(self.log_weights, self.parts)])
        resp = np.exp(lq - np.logaddexp.reduce(lq, axis=0)).mean(axis=1)
        w = np.maximum(resp, floor)
        return CompositeProposal(self.parts, np.log(w / w.sum()))

    def moments(self, random, n: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance, from n draws."""
        x = self.draw(n, random)
        return x.mean(axis=0), np.cov(x.T)

    def save(self, path: Path) -> None:
        data = {"log_weights": self.log_weights}
        for j, q in enumerate(self.parts):
            if isinstance(q, MixtureProposal):
                data.update({f"{j}_mixture_means": q.means, f"{j}_mixture_chols": q.chols,
                             f"{j}_mixture_log_weights": q.log_weights})
            else:
                data.update({f"{j}_ridge_{k}": v for k, v in q.arrays().items()})
        np.savez(path, **data)

    @classmethod
    def load(cls, path: Path) -> "CompositeProposal":
        z = np.load(path)
        parts = []
        for j in range(len(z["log_weights"])):
            if f"{j}_mixture_means" in z:
                parts.append(MixtureProposal(z[f"{j}_mixture_means"], z[f"{j}_mixture_chols"],
                                             z[f"{j}_mixture_log_weights"]))
            else:
                a = {k: z[f"{j}_ridge_{k}"] for k in ("v", "log_g", "s", "means", "slopes", "chols")}
                if f"{j}_ridge_first" in z:     # block-sparse factors (older files: dense)
                    a.update(first=z[f"{j}_ridge_first"], shared=int(z[f"{j}_ridge_shared"]))
                parts.append(RidgeProposal(index=int(z[f"{j}_ridge_index"]), **a))
        return cls(tuple(parts), z["log_weights"])


def independence_proposal(problem: Problem, theta_hat: np.ndarray, cov_hat: np.ndarray, paths) -> CompositeProposal:
    """The Laplace approximation N(θ̂, Σ̂) (weight ``CENTRAL_WEIGHT``, or 1 if no path departs) plus, in equal
    shares, a :class:`RidgeProposal` along every profile path that departs from it (:func:`path_departure`)."""
    laplace = MixtureProposal.from_components([theta_hat], [cov_hat], [0.0])
    ridges = [RidgeProposal.from_path(problem, p, flight_blocks(problem)) for p in paths
              if path_departure(p, theta_hat, cov_hat) > PROFILE_DEPARTURE]
    ridges = [r for r in ridges if r.v.size >= 2]
    if not ridges:
        return CompositeProposal((laplace,), np.zeros(1))
    lw = np.r_[np.log(CENTRAL_WEIGHT), np.full(len(ridges), np.log((1 - CENTRAL_WEIGHT) / len(ridges)))]
    return CompositeProposal((laplace, *ridges), lw)
