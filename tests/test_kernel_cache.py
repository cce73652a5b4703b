"""Compiled kernels kept on disk (bayes_disc.physics.kernel_cache) and worker pools under ``spawn``."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from bayes_disc.physics import kernel, kernel_cache, literature_coefficients, simulate
from bayes_disc.physics.codegen import hook_reference, kernel_source
from bayes_disc.physics.frames import attitude_from_yaw_pitch_roll
from bayes_disc.physics.parallel import ENV_START_METHOD, mp_context, start_method
from bayes_disc.physics.tableaux import get_tableau
from bayes_disc.physics.terms import TERMS, Term, TermParameter

REPO = Path(__file__).resolve().parents[1]
TIMES = np.arange(0.0, 0.5, 1 / 120)
MARKERS = np.array([[0.1, 0.0, -0.015], [-0.0308, 0.0846, -0.015], [-0.0707, -0.0778, -0.015]])


def _state(spin=-60.0):
    q = attitude_from_yaw_pitch_roll(0.1, 0.15, -0.05)
    return np.concatenate([[0, 0, 1.5], [13.0, 0.5, 2.0], q, [2.0, -1.0, spin]])


def _run_markers(spin=-60.0):
    return simulate(_state(spin), literature_coefficients("hummel2002"), TIMES, marker_body=MARKERS).markers


def test_cache_root_from_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(kernel_cache.ENV_CACHE_DIR, str(tmp_path / "c"))
    assert kernel_cache.cache_root() == tmp_path / "c"
    monkeypatch.delenv(kernel_cache.ENV_CACHE_DIR)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert kernel_cache.cache_root() == tmp_path / "xdg" / "bayes-disc"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert kernel_cache.cache_root() == Path.home() / ".cache" / "bayes-disc"


def test_write_once_is_atomic_and_never_rewrites_the_same_text(tmp_path):
    path = tmp_path / "k.py"
    assert kernel_cache.write_once(path, "a = 1\n")
    stamp = path.stat().st_mtime_ns
    assert not kernel_cache.write_once(path, "a = 1\n")          # same text: left alone (numba's stamp)
    assert path.stat().st_mtime_ns == stamp
    assert kernel_cache.write_once(path, "a = 2\n")              # wrong content: replaced
    assert path.read_text() == "a = 2\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.py"]  # no temporary files left


def test_key_depends_on_terms_method_and_width():
    vern = get_tableau("vern7")
    keys = {kernel_cache.kernel_key(kernel_source(terms, tab, lanes))
            for terms in ((), (TERMS["wind"],)) for tab in (vern, get_tableau("rk4")) for lanes in (4, 8)}
    assert len(keys) == 8
    assert kernel_cache.kernel_key(kernel_source((), vern, 4)) == kernel_cache.kernel_key(kernel_source((), vern, 4))


def test_hooks_defined_inside_a_function_are_not_importable():
    import numba as nb

    @nb.njit(inline="always")
    def local_air(E, off, t, x, y, z):
        return (E[off], 0.0, 0.0)

    assert hook_reference(TERMS["wind"].air) == ("bayes_disc.physics.terms", "_wind_air")
    assert hook_reference(local_air) is None
    term = Term(id="local", title="t", equations="e", parameters=(TermParameter("w", "m/s", "w"),), air=local_air)
    src = kernel_source((term,), get_tableau("rk4"), 4)
    assert not src.importable and "__hooks__[0]" in src.text


_CHILD = """
import json, sys, numpy as np
sys.path.insert(0, {repo!r})
from bayes_disc.physics import kernel, literature_coefficients, simulate
from bayes_disc.physics.frames import attitude_from_yaw_pitch_roll
q = attitude_from_yaw_pitch_roll(0.1, 0.15, -0.05)
y0 = np.concatenate([[0, 0, 1.5], [13.0, 0.5, 2.0], q, [2.0, -1.0, -60.0]])
mb = np.array({markers!r})
tr = simulate(y0, literature_coefficients("hummel2002"), np.arange(0.0, 0.5, 1 / 120), marker_body=mb)
(k,) = kernel._KERNELS.values()
print(json.dumps({{"hits": sum(k.stats.cache_hits.values()), "misses": sum(k.stats.cache_misses.values()),
                  "markers": tr.markers.tolist(), "file": k.py_func.__code__.co_filename}}))
"""


def _child(cache_dir: Path) -> dict:
    env = {**os.environ, kernel_cache.ENV_CACHE_DIR: str(cache_dir)}
    code = _CHILD.format(repo=str(REPO), markers=MARKERS.tolist())
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_new_process_loads_the_compiled_kernel_from_disk(tmp_path):
    cold = _child(tmp_path)
    warm = _child(tmp_path)
    assert cold["hits"] == 0 and cold["misses"] >= 1
    assert warm["hits"] >= 1 and warm["misses"] == 0, warm
    assert Path(cold["file"]).parent == tmp_path / "kernels"
    here = _run_markers()
    np.testing.assert_array_equal(np.array(cold["markers"]), here)    # bit-identical to in-process
    np.testing.assert_array_equal(np.array(warm["markers"]), here)


def test_unwritable_cache_dir_warns_and_gives_the_same_results(tmp_path, monkeypatch):
    expected = _run_markers()
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv(kernel_cache.ENV_CACHE_DIR, str(blocker / "cache"))
    monkeypatch.setattr(kernel, "_KERNELS", {})
    with pytest.warns(RuntimeWarning, match="not writable"):
        got = _run_markers()
    np.testing.assert_array_equal(got, expected)


# --- worker pools under spawn -------------------------------------------------------------------------

def _simulate_task(spin):
    return _run_markers(spin)


def _problem():
    from bayes_disc.inference.model.initial import initial_state_from_data
    from bayes_disc.inference.model.problem import Problem
    from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize
    spec = SynthSpec(name="s", flights=(LaunchSpec(name="a", speed=13.0, launch_angle_deg=4, alpha_deg=6,
                                                   spin=60, duration=0.6, noise_mm=1.0),), seed=3)
    data = synthesize(spec)
    mb = np.array(list(DEFAULT_MARKERS.values()))
    start = initial_state_from_data(data.flights[0], mb)
    problem = Problem(flights=data.flights, marker_body=mb, disc=spec.disc, env=spec.env, prior_name="weak",
                      start_states=[start])
    theta = np.zeros(problem.dim)
    theta[:10] = literature_coefficients("hummel2002").as_array()
    theta[problem.ic_slice(0)] = problem.state_to_ic(start, 0)
    return problem, theta


def _residual_task(args):
    from bayes_disc.inference.fitting.residuals import whitened_residuals
    problem, x = args
    return whitened_residuals(x, problem, np.array([1e-3]))


def test_pools_work_under_spawn():
    from bayes_disc.inference.fitting.residuals import whitened_residuals
    problem, theta = _problem()
    spins = [-40.0, -60.0]
    here_sim = [_simulate_task(s) for s in spins]
    xs = [theta, theta * np.where(np.arange(theta.size) < 10, 1.05, 1.0)]
    here_res = [whitened_residuals(x, problem, np.array([1e-3])) for x in xs]
    import multiprocessing as mp
    with mp.get_context("spawn").Pool(2) as pool:
        sims = pool.map(_simulate_task, spins)
        res = pool.map(_residual_task, [(problem, x) for x in xs])
    for a, b in zip(sims, here_sim):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(res, here_res):
        assert np.all(np.isfinite(b))
        np.testing.assert_array_equal(a, b)


def test_start_method_from_environment(monkeypatch):
    monkeypatch.setenv(ENV_START_METHOD, "spawn")
    assert start_method() == "spawn" and mp_context().get_start_method() == "spawn"
    monkeypatch.setenv(ENV_START_METHOD, "teleport")
    with pytest.raises(ValueError, match="teleport"):
        start_method()
    monkeypatch.delenv(ENV_START_METHOD)
    assert start_method() in ("fork", "spawn")
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # no deprecation noise from the default choice
        mp_context()
