"""Benchmark of the profile-likelihood fits (issue 18): Jacobians per point, time of the profile stage and
the fits' accuracy, for four settings of the fits, on ``bench_scale.py``'s synthetic data sets:

* ``far, cost stop``: Levenberg–Marquardt started at the far-start damping (``minimiser.MU_FAR``, 10⁻³), stopped
  when a step lowers the deviance by less than ``profile.DEVIANCE_TOL``, the point's covariance from one more
  Jacobian (every fit before stop 39);
* ``near, cost stop``: the same from the near-start damping (``MU_NEAR``, 10⁻⁶: stop 39);
* ``near, decrement stop``: also stopped once the Gauss–Newton decrement is at most
  ``profile.DECREMENT_TOL``, the covariance from the fit's last Jacobian (stop 40; since stop 42 also after a
  cost stop, one small step before the point);
* ``near, decrement stop, final step``: also stopped after one more step from a decrement at most
  ``profile.FINAL_DECREMENT`` whose gain is as predicted (stop 42: the default).

For each flight count: the data set, least squares, then the profile paths of the ten coefficients in one
process, once per setting, in rotating order over ``--repeats`` rounds (times: medians). Printed per
setting: profile points, fits, Jacobians per fit and per point (the fit's and the covariance's), the
stage's time, and the deviance error of every point that is ``ok`` — its deviance minus that of a tight
refit from it (xtol = ftol = 10⁻¹³), which is ≥ 0: how far short of the constrained optimum the fit
stopped. The smallest eigenvalues of the scale-free information matrix at the optimum say which ridge
directions a damping of μ₀ relative to the diagonal holds back.

    python benchmarks/bench_profile_fits.py [--flights 4 24] [--seed 18] [--repeats 1]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_scale import write_case  # noqa: E402

from bayes_disc.inference.fitting import leastsq, minimiser, profile, residuals  # noqa: E402
from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402


class _Counted:
    """``minimiser.minimise`` counting its fits and Jacobians (put in place of profile.minimise), and
    ``residuals.jacobian_blocks`` counting the covariance Jacobians the profile computes itself (in place of
    profile.jacobian_blocks)."""

    def __init__(self):
        self.fits = self.jacobians = self.extra = 0

    def __call__(self, *args, **kwargs):
        res = minimiser.minimise(*args, **kwargs)
        self.fits += 1
        self.jacobians += res.njev
        return res

    def jacobian_blocks(self, *args, **kwargs):
        self.extra += 1
        return residuals.jacobian_blocks(*args, **kwargs)


SETTINGS = {"far, cost stop": dict(mu0=minimiser.MU_FAR, dtol=0.0),
            "near, cost stop": dict(mu0=minimiser.MU_NEAR, dtol=0.0),
            "near, decrement stop": dict(mu0=minimiser.MU_NEAR, dtol=profile.DECREMENT_TOL, final=0.0),
            "near, decrement stop, final step": dict(mu0=minimiser.MU_NEAR, dtol=profile.DECREMENT_TOL,
                                                     final=profile.FINAL_DECREMENT)}


def deviance_errors(problem, ls, paths, cost0: float) -> np.ndarray:
    """Every ok point's deviance minus a tight refit's from it (all parameters but the profiled one free)."""
    out = []
    for path in paths:
        for point in path.points:
            if point.t == 0.0 or not point.ok:
                continue
            free = np.ones(problem.dim, bool)
            free[path.index] = False
            tight = minimiser.minimise(problem, point.theta, ls.sigma, free=free, max_nfev=100, xtol=1e-13, ftol=1e-13,
                                     mu0=minimiser.MU_NEAR)
            out.append(point.deviance - 2.0 * (tight.cost - cost0))
    return np.array(out)


def one_case(n: int, seed: int, repeats: int, tmp: Path) -> None:
    folder = tmp / f"f{n}"
    folder.mkdir()
    cfg = load_config(write_case(folder, n, seed, ""))
    problem = build_problem(cfg)
    ls = leastsq.fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev)
    r0 = residuals.whitened_residuals(ls.theta, problem, ls.sigma)
    cost0 = 0.5 * float(r0 @ r0)
    scaled = residuals.jacobian_blocks(ls.theta, problem, ls.sigma).information().scaled()[0].dense()
    ev = np.linalg.eigvalsh(scaled)[:3]
    print(f"{n} flights ({problem.dim} parameters): smallest eigenvalues of the scale-free information "
          f"{', '.join(f'{e:.2g}' for e in ev)}", flush=True)
    indices = range(problem.n_coef + problem.n_ext)
    names = list(SETTINGS)
    times = {k: [] for k in names}
    result = {}
    for r in range(repeats):
        for name in names[r % len(names):] + names[: r % len(names)]:
            counted = _Counted()
            profile.minimise, profile.jacobian_blocks = counted, counted.jacobian_blocks
            try:
                t0 = time.perf_counter()
                paths = profile.profile_paths(problem, ls.theta, ls.sigma, ls.cov, indices, processes=1,
                                              **SETTINGS[name])
                times[name].append(time.perf_counter() - t0)
            finally:
                profile.minimise, profile.jacobian_blocks = minimiser.minimise, residuals.jacobian_blocks
            result[name] = (paths, counted)
    for name, (paths, counted) in result.items():
        err = deviance_errors(problem, ls, paths, cost0)
        points = sum(len(p.points) - 1 for p in paths)
        print(f"  {name}: {points} points, {counted.fits} fits, {counted.jacobians / counted.fits:.2f} Jacobians "
              f"per fit, {(counted.jacobians + counted.extra) / max(points, 1):.2f} per point, profiles "
              f"{np.median(times[name]):.1f} s (median of {len(times[name])}); deviance short of the constrained "
              f"optimum: median {np.median(err):.1e}, 90 % {np.percentile(err, 90):.1e}, max {err.max():.1e} "
              f"({err.size} points)", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, nargs="+", default=[4, 24])
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.flights:
            one_case(n, args.seed, args.repeats, Path(tmp))
    return 0


if __name__ == "__main__":
    sys.exit(main())
