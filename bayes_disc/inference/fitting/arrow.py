"""Block-arrow normal equations of the joint fit over many flights.

Flight k's residuals r_k depend only on the shared parameters θ_s (coefficients, extension block) and on
the flight's own θ_k (initial conditions, its own observation-model parameters); the prior is diagonal.
The whitened Jacobian is therefore block-sparse,

    J = [ J_1s  J_1k   0    …        (flight 1's rows)
          J_2s   0    J_2k  …        (flight 2's rows)
          P_s    0     0    …        (prior rows: diagonal, 1/sd)
           0    P_1    0    …  ]

and the information (Gauss–Newton Hessian) H = JᵀJ is an arrow:

    H = [ A     B_1   B_2  …         A   = Σ_k J_ksᵀ J_ks + P_s²        (s × s)
          B_1ᵀ  C_1    0             B_k = J_ksᵀ J_kk                    (s × p_k)
          B_2ᵀ   0    C_2            C_k = J_kkᵀ J_kk + P_k²            (p_k × p_k)
          …                   ]

Eliminating each flight's block (Schur complement S = A − Σ_k B_k C_k⁻¹ B_kᵀ) solves H δ = g in
O(Σ_k n_k (s + p_k)² + Σ_k p_k³ + s³) operations and O(Σ_k n_k (s + p_k)) memory: linear in the number of
flights, where the dense solve of J (N × dim) is O(N dim²), quadratic. Every solve works on the
Jacobi-scaled matrix D⁻¹ H D⁻¹ (D = √diag H; the entries of H span ~12 decades, CNr beside positions),
where Levenberg–Marquardt's damping H + μ diag(H) is the identity shift μ I.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve


@dataclass(frozen=True)
class ArrowMatrix:
    """A symmetric positive (semi-)definite block-arrow matrix over n unknowns.

    Parameters
    ----------
    shared : (s,) int array
        Positions of the shared unknowns among the n.
    own : tuple of (p_k,) int arrays
        Positions of each block's own unknowns (disjoint, together with ``shared`` covering 0 … n−1).
    A : (s, s) array
        Shared–shared block.
    B : tuple of (s, p_k) arrays
        Shared–own coupling of each block.
    C : tuple of (p_k, p_k) arrays
        Each block's own–own matrix.
    """

    shared: np.ndarray
    own: tuple
    A: np.ndarray
    B: tuple
    C: tuple

    @property
    def n(self) -> int:
        return int(self.shared.size + sum(o.size for o in self.own))

    def diagonal(self) -> np.ndarray:
        """(n,) the diagonal of the matrix."""
        d = np.empty(self.n)
        d[self.shared] = np.diag(self.A)
        for o, C in zip(self.own, self.C):
            d[o] = np.diag(C)
        return d

    def dense(self) -> np.ndarray:
        """(n, n) the full matrix (for small problems, reports and tests)."""
        H = np.zeros((self.n, self.n))
        H[np.ix_(self.shared, self.shared)] = self.A
        for o, B, C in zip(self.own, self.B, self.C):
            H[np.ix_(self.shared, o)] = B
            H[np.ix_(o, self.shared)] = B.T
            H[np.ix_(o, o)] = C
        return H

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """H x for x (n,)."""
        out = np.empty(self.n)
        xs = x[self.shared]
        ys = self.A @ xs
        for o, B, C in zip(self.own, self.B, self.C):
            ys += B @ x[o]
            out[o] = B.T @ xs + C @ x[o]
        out[self.shared] = ys
        return out

    def scaled(self) -> tuple["ArrowMatrix", np.ndarray]:
        """(D⁻¹ H D⁻¹, d): the unit-diagonal matrix and d = √diag H (entries ≤ 0 taken as 1)."""
        d = self.diagonal()
        d = np.sqrt(np.where(d > 0, d, 1.0))
        ds = d[self.shared]
        return ArrowMatrix(self.shared, self.own, self.A / np.outer(ds, ds),
                           tuple(B / np.outer(ds, d[o]) for o, B in zip(self.own, self.B)),
                           tuple(C / np.outer(d[o], d[o]) for o, C in zip(self.own, self.C))), d

    def solve(self, g: np.ndarray, damping: float = 0.0) -> np.ndarray:
        """x with (H + damping · diag H) x = g, by Schur elimination of every block.

        Parameters
        ----------
        g : (n,) array
            Right-hand side.
        damping : float
            Levenberg–Marquardt's μ ≥ 0 (relative to the diagonal).

        Returns
        -------
        (n,) array

        Raises
        ------
        numpy.linalg.LinAlgError
            The (damped) matrix is not positive definite.
        """
        Hs, d = self.scaled()
        gs = g / d
        shift = 1.0 + damping
        S = Hs.A + (shift - 1.0) * np.eye(Hs.A.shape[0])
        rhs = gs[self.shared].copy()
        factors = []
        for o, B, C in zip(self.own, Hs.B, Hs.C):
            f = _cholesky(C + (shift - 1.0) * np.eye(C.shape[0]))
            CiBt = cho_solve(f, B.T)               # C_k⁻¹ B_kᵀ   (p_k, s)
            Cig = cho_solve(f, gs[o])             # C_k⁻¹ g_k    (p_k,)
            S -= B @ CiBt
            rhs -= B @ Cig
            factors.append((CiBt, Cig))
        x = np.empty(self.n)
        xs = cho_solve(_cholesky(S), rhs)
        x[self.shared] = xs
        for o, (CiBt, Cig) in zip(self.own, factors):
            x[o] = Cig - CiBt @ xs
        return x / d

    def schur(self) -> np.ndarray:
        """(s, s) S = A − Σ_k B_k C_k⁻¹ B_kᵀ: the shared unknowns' information with every block's own
        unknowns marginalised (C_k pseudo-inverted in scale-free form)."""
        Hs, d = self.scaled()
        S = Hs.A.copy()
        for B, C in zip(Hs.B, Hs.C):
            S -= B @ _pinv_sym(C) @ B.T
        ds = d[self.shared]
        return S * np.outer(ds, ds)

    def inverse(self) -> np.ndarray:
        """(n, n) H⁻¹ (pseudo-inverse in scale-free form: a direction with no information gets variance 0
        rather than an error), assembled block by block:

            (H⁻¹)_ss = S⁻¹,   (H⁻¹)_sk = −S⁻¹ B_k C_k⁻¹,   (H⁻¹)_kl = δ_kl C_k⁻¹ + C_k⁻¹ B_kᵀ S⁻¹ B_l C_l⁻¹
        """
        Hs, d = self.scaled()
        Ci = [_pinv_sym(C) for C in Hs.C]
        S = Hs.A.copy()
        for B, Cinv in zip(Hs.B, Ci):
            S -= B @ Cinv @ B.T
        Si = _pinv_sym(S)
        out = np.zeros((self.n, self.n))
        out[np.ix_(self.shared, self.shared)] = Si
        if self.own:
            own = np.concatenate(self.own)
            G = np.concatenate([Cinv @ B.T for B, Cinv in zip(Hs.B, Ci)])   # C_k⁻¹ B_kᵀ stacked   (Σp_k, s)
            cross = -Si @ G.T                                                # (s, Σp_k)
            out[np.ix_(self.shared, own)] = cross
            out[np.ix_(own, self.shared)] = cross.T
            out[np.ix_(own, own)] = G @ Si @ G.T                             # every (k, l) pair at once
            for o, Cinv in zip(self.own, Ci):
                out[np.ix_(o, o)] += Cinv
        return out / np.outer(d, d)

    def condition_number(self) -> float:
        """Condition number of the scale-free matrix D⁻¹ H D⁻¹ (dense eigenvalues: O(n³), n ≲ a few
        hundred parameters)."""
        ev = np.linalg.eigvalsh(self.scaled()[0].dense())
        return float(ev[-1] / max(ev[0], 1e-300))


def _cholesky(M: np.ndarray):
    return cho_factor(0.5 * (M + M.T), lower=True, check_finite=True)


def _pinv_sym(M: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a symmetric matrix (eigenvalues below 1e-15 of the largest dropped; a 0 × 0 matrix,
    when every shared parameter is held, is its own)."""
    if M.size == 0:
        return M.copy()
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    keep = w > 1e-15 * max(w[-1], 1e-300)
    return (V[:, keep] / w[keep]) @ V[:, keep].T


@dataclass(frozen=True)
class ArrowJacobian:
    """A whitened Jacobian in block form: per block k, the rows of its residuals against its shared and
    own unknowns, then the diagonal prior rows.

    Parameters
    ----------
    shared : (s,) int array
        Positions of the shared unknowns among the n.
    own : tuple of (p_k,) int arrays
        Positions of each block's own unknowns.
    blocks : tuple of (n_k, s + p_k) arrays
        Block k's rows; columns: the shared unknowns (in ``shared`` order), then its own.
    prior : (n,) array
        The prior rows' diagonal 1/sd (0 for none).
    """

    shared: np.ndarray
    own: tuple
    blocks: tuple
    prior: np.ndarray

    @property
    def n(self) -> int:
        return int(self.prior.size)

    def information(self) -> ArrowMatrix:
        """H = JᵀJ (prior rows included), as an :class:`ArrowMatrix`."""
        s = self.shared.size
        A = np.diag(self.prior[self.shared] ** 2)
        B, C = [], []
        for o, J in zip(self.own, self.blocks):
            Js, Jk = J[:, :s], J[:, s:]
            A += Js.T @ Js
            B.append(Js.T @ Jk)
            C.append(Jk.T @ Jk + np.diag(self.prior[o] ** 2))
        return ArrowMatrix(self.shared, tuple(self.own), A, tuple(B), tuple(C))

    def select(self, keep: np.ndarray) -> "ArrowJacobian":
        """The Jacobian over the unknowns ``keep`` only: their columns, renumbered in their order.

        Parameters
        ----------
        keep : (n,) bool array
            Unknowns kept.

        Returns
        -------
        ArrowJacobian
            Over ``keep.sum()`` unknowns; every block keeps its rows.
        """
        keep = np.asarray(keep, bool)
        position = np.cumsum(keep) - 1
        in_shared = keep[self.shared]
        own, blocks = [], []
        for o, J in zip(self.own, self.blocks):
            own.append(position[o[keep[o]]])
            blocks.append(np.ascontiguousarray(J[:, np.r_[in_shared, keep[o]]]))
        return ArrowJacobian(shared=position[self.shared[in_shared]], own=tuple(own), blocks=tuple(blocks),
                             prior=self.prior[keep])

    def block_schur(self) -> list[np.ndarray]:
        """Per block k, its information about the shared unknowns with its own marginalised,

            S_k = J_ksᵀ J_ks − B_k C_k⁻¹ B_kᵀ,   B_k = J_ksᵀ J_kk,   C_k = J_kkᵀ J_kk + P_k²

        (s × s each; C_k pseudo-inverted in scale-free form): what flight k alone says about the shared
        parameters, its own initial conditions unknown. Σ_k S_k + P_s² is :meth:`ArrowMatrix.schur`.

        Returns
        -------
        list of (s, s) arrays
        """
        s = self.shared.size
        out = []
        for o, J in zip(self.own, self.blocks):
            Js, Jk = J[:, :s], J[:, s:]
            C = Jk.T @ Jk + np.diag(self.prior[o] ** 2)
            d = np.sqrt(np.where(np.diag(C) > 0, np.diag(C), 1.0))
            B = Js.T @ Jk
            out.append(Js.T @ Js - (B / d) @ _pinv_sym(C / np.outer(d, d)) @ (B / d).T)
        return out

    def gradient(self, residuals, prior_residual: np.ndarray) -> np.ndarray:
        """Jᵀ r for the blocks' residuals (tuple of (n_k,)) and the prior rows' residuals (n,)."""
        s = self.shared.size
        g = self.prior * prior_residual
        for o, J, r in zip(self.own, self.blocks, residuals):
            g[self.shared] += J[:, :s].T @ r
            g[o] += J[:, s:].T @ r
        return g

    def dense(self) -> np.ndarray:
        """(Σ n_k + n, n) the full Jacobian: blocks' rows, then the prior rows."""
        s = self.shared.size
        rows = []
        for o, J in zip(self.own, self.blocks):
            D = np.zeros((J.shape[0], self.n))
            D[:, self.shared] = J[:, :s]
            D[:, o] = J[:, s:]
            rows.append(D)
        rows.append(np.diag(self.prior))
        return np.vstack(rows)
