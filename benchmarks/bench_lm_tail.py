"""Why least squares takes more Jacobians as flights are added (issue 18): the Levenberg–Marquardt path of
one start, step by step.

For a kept ``bench_scale.py`` case (``DIR/f<flights>``, its config.yaml), or any run configuration, the
minimiser's steps from the first least-squares start are replayed with the same damping rule as
:func:`bayes_disc.inference.fitting.minimiser.minimise` (Nielsen's update of μ after an accepted step; μ × ν, ν
doubling, after a rejected one) and, per step, printed:

* the cost above the final optimum's (½ Σ whitened residual², prior included);
* the gain ratio ρ = actual / predicted decrease (the Gauss–Newton model's);
* t* = 1 / (2 − ρ): along the step, where the cost's parabola through c(0), c′(0) and c(1) has its
  minimum — how far off the Gauss–Newton curvature is along the step (t* < 1: the step overshoots; t* > 1:
  the model's curvature is too large, the residuals' own curvature Σ r ∇²r that Gauss–Newton drops is
  negative there);
* the cost at 0.5, 1.5 and 2 steps relative to c(0), which checks t* (``--probe``; three more residual
  evaluations per step).

    python benchmarks/bench_lm_tail.py DIR/f24 [--steps 30] [--probe]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.fitting import leastsq, minimiser, residuals  # noqa: E402
from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402


def cost(problem, sigma, x) -> tuple[float, list, np.ndarray]:
    """(½ Σ r², per-flight whitened residuals, the prior's standardised deviations) at x (dim,)."""
    parts = residuals.flight_residuals(x, problem, sigma)
    prior = (x - problem.prior_mean) / problem.prior_sd
    return 0.5 * float(sum(p @ p for p in parts) + prior @ prior), parts, prior


def model_decrease(J, g: np.ndarray, step: np.ndarray) -> float:
    """−(gᵀδ + ½ |J δ|²): the Gauss–Newton model's predicted decrease for a step δ (n,)."""
    s = J.shared.size
    quad = sum(float(np.sum((B[:, :s] @ step[J.shared] + B[:, s:] @ step[o]) ** 2)) for o, B in zip(J.own, J.blocks))
    quad += float(np.sum((J.prior * step) ** 2))
    return -(float(g @ step) + 0.5 * quad)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path, help="a folder with config.yaml (e.g. a kept bench_scale case DIR/f24)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--probe", action="store_true", help="also evaluate the cost at 0.5, 1.5 and 2 steps")
    args = ap.parse_args(argv)
    problem = build_problem(load_config(args.case / "config.yaml"))
    sigma = problem.nominal_noise
    x = leastsq._starts(problem, 1, np.random.default_rng(0))[0]
    final = minimiser.minimise(problem, x, sigma)
    print(f"{args.case}: {problem.n_flights} flights, {problem.dim} parameters; minimise from the first start: "
          f"{final.njev} Jacobians, cost {final.cost:.6f} ({final.message})")
    mu, nu, J = 1e-3, 2.0, None
    for it in range(args.steps):
        if J is None:
            c0, parts, prior = cost(problem, sigma, x)
            J = residuals.jacobian_blocks(x, problem, sigma)
            g = J.gradient(parts, prior)
            H = J.information()
        step = H.solve(-g, mu)
        c1 = cost(problem, sigma, x + step)[0]
        rho = (c0 - c1) / model_decrease(J, g, step)
        line = (f"step {it:2d}  cost − optimum {c0 - final.cost:10.4g}  μ {mu:8.2e}  ρ {rho:5.2f}  "
                f"t* {1 / (2 - rho) if rho < 2 else np.inf:5.2f}")
        if args.probe:
            line += "  c(t) − c(0): " + "  ".join(f"{t}: {cost(problem, sigma, x + t * step)[0] - c0:9.3g}"
                                                  for t in (0.5, 1.5, 2.0))
        if rho > 0:             # minimise's rule: accept, μ by Nielsen's update
            mu, nu, J, x = mu * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0, None, x + step
        else:                   # reject: more damping, the same Jacobian
            mu, nu = mu * nu, nu * 2
            line += "  (rejected)"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
