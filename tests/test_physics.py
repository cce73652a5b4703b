"""Physics checks that can fail: conservation laws, the parabola, mirror symmetry, solve_ivp agreement,
wild parameters."""
import platform

import numpy as np
import pytest

from bayes_disc.physics import (Disc, Environment, SimulatorSettings, get_terms, literature_coefficients,
                                simulate, simulate_reference)
from bayes_disc.physics.equations import angular_momentum_world, kinetic_energy
from bayes_disc.physics.frames import (attitude_from_yaw_pitch_roll, omega_body_from_pqr, quat_from_rotvec,
                                      quat_multiply, quat_to_matrix)
from bayes_disc.observation.synth import DEFAULT_MARKERS

MARKERS = np.array(list(DEFAULT_MARKERS.values()))
HUMMEL = literature_coefficients("hummel2002").as_array()


def _state(speed=13.0, gamma=0.05, pitch=0.12, roll=0.08, pqr=(3.0, -2.0, 55.0)):
    v = speed * np.array([np.cos(gamma), 0.0, np.sin(gamma)])
    q = attitude_from_yaw_pitch_roll(0.1, pitch, roll)
    return np.concatenate([[0.0, 0.0, 1.0], v, q, omega_body_from_pqr(pqr, v, q)])


def _conservation_errors(y0, t, disc, env, settings):
    states = simulate(y0, np.zeros(10), t, disc=disc, env=env, settings=settings).states[0]
    energy = np.array([kinetic_energy(s, disc) + disc.mass * env.g * s[2] for s in states])
    H = np.array([angular_momentum_world(s, disc) for s in states])
    return np.abs(energy / energy[0] - 1).max(), np.abs(H - H[0]).max() / np.linalg.norm(H[0])


def test_quaternion_product_composes_rotations_and_broadcasts():
    """R(a ⊗ b) = R(a) R(b) (Hamilton convention, v_W = R v_B), for one quaternion against a batch, a batch
    against one, and batches of matching shapes."""
    rng = np.random.default_rng(3)
    a = quat_from_rotvec(rng.normal(size=(5, 2, 3)))
    b = quat_from_rotvec(rng.normal(size=(5, 2, 3)))
    ab = quat_multiply(a, b)
    assert ab.shape == (5, 2, 4)
    np.testing.assert_allclose(quat_to_matrix(ab), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-14)
    one = a[0, 0]
    np.testing.assert_allclose(quat_multiply(one, b), np.stack([quat_multiply(one, q) for q in b.reshape(-1, 4)]
                                                               ).reshape(b.shape), atol=0)
    np.testing.assert_allclose(quat_multiply(b, one)[3, 1], quat_multiply(b[3, 1], one), atol=0)
    np.testing.assert_allclose(quat_multiply([1.0, 0, 0, 0], b), b, atol=0)     # identity


def test_torque_free_drag_free_conserves_energy_and_angular_momentum():
    """Total energy (kinetic + m g z) and world angular momentum are invariants without aerodynamics.
    On a 120 Hz grid at the default step they hold to 1e-6 relative; the drift is truncation error,
    so on a sparse output grid (where the step factor sets the step) it must shrink at least 16-fold
    (≥ 4th order) when the step is halved."""
    disc, env = Disc(), Environment()
    y0 = _state(pqr=(6.0, -4.0, 40.0))  # strong wobble
    default = SimulatorSettings()
    e_rated, h_rated = _conservation_errors(y0, np.arange(241) / 120.0, disc, env, default)
    assert e_rated < 1e-6 and h_rated < 1e-6
    sparse = np.linspace(0.0, 2.0, 5)
    coarse = SimulatorSettings(method=default.method, step_factor=2 * default.c)
    e1, h1 = _conservation_errors(y0, sparse, disc, env, coarse)
    e2, h2 = _conservation_errors(y0, sparse, disc, env, default)
    assert e1 > 1e-9, "the coarse run must be above round-off for the order check to mean anything"
    assert e2 < e1 / 16 and h2 < h1 / 16
    # the test can fail: with aerodynamics on, energy is not conserved
    tr_aero = simulate(y0, HUMMEL, np.arange(241) / 120.0, disc=disc, env=env)
    e_aero = kinetic_energy(tr_aero.states[0, -1], disc) + disc.mass * env.g * tr_aero.states[0, -1, 2]
    e0 = kinetic_energy(y0, disc) + disc.mass * env.g * y0[2]
    assert abs(e_aero / e0 - 1) > 1e-3


def test_gravity_only_gives_exact_parabola():
    env = Environment()
    y0 = _state()
    t = np.linspace(0, 2.0, 97)
    tr = simulate(y0, np.zeros(10), t, env=env)
    expect = y0[:3] + np.outer(t, y0[3:6]) - 0.5 * env.g * np.outer(t**2, [0, 0, 1])
    assert np.abs(tr.states[0, :, :3] - expect).max() < 1e-10


def test_mirrored_throw_gives_mirrored_path():
    """Reflect y → −y: positions and velocities mirror, ω (axial) becomes −Mω, the attitude M R M and the
    markers M m_B; with the same coefficients (roll terms included) every marker path mirrors."""
    M = np.diag([1.0, -1.0, 1.0])
    y0 = _state(pqr=(2.0, -1.5, 60.0))
    R = quat_to_matrix(y0[6:10])
    from bayes_disc.physics.frames import matrix_to_quat
    y_m = np.concatenate([M @ y0[:3], M @ y0[3:6], matrix_to_quat(M @ R @ M), -(M @ y0[10:13])])
    t = np.arange(181) / 120.0
    a = simulate(y0, HUMMEL, t, marker_body=MARKERS)
    b = simulate(y_m, HUMMEL, t, marker_body=MARKERS @ M)
    mirrored = a.markers[0] @ M
    assert np.abs(b.markers[0] - mirrored).max() < 1e-9
    # sanity: the throw does curve sideways, so the mirror test has something to check
    assert np.abs(a.states[0, -1, 1]) > 0.05


#: parameter values that make each term's effect clearly visible over 1.5 s
#: (shape parameters of the families away from their off values too)
TERM_VALUES = {"side_force": [0.3, 0.8], "wind": [1.5, -2.0, 0.3, 0.5, -0.4], "ground_effect": [0.4, 0.2, 0.3],
               "nonlinear_aero": [-1.5, 1.0, 0.3, 1.0, -2.0, 0.5], "spin_lift": [0.3, 1.2],
               "roll_spin_coupling": [0.02, 0.9], "inertia_ratio": [-0.05], "rate_coupling": [-0.006, 0.004],
               "rate_damping": [-0.03, -0.002], "disc_asymmetry": [0.01, -0.008]}


@pytest.mark.parametrize("terms", [(), ("side_force", "wind"), ("ground_effect",), ("nonlinear_aero",),
                                   ("spin_lift", "roll_spin_coupling"), ("inertia_ratio", "rate_coupling", "rate_damping")])
def test_kernel_agrees_with_solve_ivp_dop853(terms):
    y0 = _state(pqr=(4.0, -3.0, 50.0))
    t = np.arange(0, 181) / 120.0 + 0.3
    ext = np.array([v for name in terms for v in TERM_VALUES[name]])
    terms = get_terms(terms)
    fast = simulate(y0, HUMMEL, t, t0=0.3, marker_body=MARKERS, terms=terms, extension=ext if ext.size else None)
    ref = simulate_reference(y0, HUMMEL, t, t0=0.3, marker_body=MARKERS, terms=terms,
                             extension=ext if ext.size else None)
    assert np.abs(fast.markers - ref.markers).max() < 1e-6


@pytest.mark.parametrize("name", sorted(TERM_VALUES))
def test_every_term_is_off_at_its_off_value_and_changes_the_flight_otherwise(name):
    (term,) = get_terms([name])
    y0 = _state(pqr=(0.0, 0.0, 50.0))
    t = np.arange(121) / 120.0
    base = simulate(y0, HUMMEL, t, marker_body=MARKERS)
    off = simulate(y0, HUMMEL, t, marker_body=MARKERS, terms=(term,), extension=[p.off_value for p in term.parameters])
    on = simulate(y0, HUMMEL, t, marker_body=MARKERS, terms=(term,), extension=TERM_VALUES[name])
    assert np.abs(off.markers - base.markers).max() < 1e-12
    assert np.abs(on.markers - base.markers).max() > 0.01, name   # > 1 cm after 1 s
    assert term.equations and all(p.unit and p.prior_sd > 0 for p in term.parameters)
    # extra lift lifts the disc, less lift drops it (final height of the centre of mass)
    sign = {"spin_lift": 1, "nonlinear_aero": -1}.get(name)
    if sign is not None:
        assert sign * (on.markers[0, -1, :, 2].mean() - base.markers[0, -1, :, 2].mean()) > 0.005, name


def _every_term():
    """The fitted terms, the synthetic truths' forms and the learned correction: every term a kernel can carry."""
    from bayes_disc.physics.discrepancy import DISCREPANCY
    from bayes_disc.physics.nature import NATURE
    from bayes_disc.physics.terms import TERMS
    return [*TERMS.values(), *NATURE.values(), DISCREPANCY]


@pytest.mark.parametrize("term", _every_term(), ids=lambda t: t.id)
def test_hooks_the_kernel_skips_at_the_off_values_add_nothing_there(term):
    """A kernel skips a term's hooks in a lane whose parameters all sit at their off values, which is exact
    only if the hooks return zero there: checked on the hooks themselves, in random flight contexts."""
    from bayes_disc.physics.terms import CTX_SIZE
    E = np.array([p.off_value for p in term.parameters], float)
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(300):
        ctx = tuple(rng.normal(size=CTX_SIZE) * 3.0)
        if term.loads is not None:
            worst = max(worst, np.abs(term.loads.py_func(E, 0, ctx)).max())
        if term.air is not None:
            worst = max(worst, np.abs(term.air.py_func(E, 0, *rng.normal(size=4) * 3.0)).max())
    if term.zero_when_off:
        assert worst == 0.0, term.id
    else:
        assert worst > 0.0, f"{term.id} is zero at its off values: the kernel may skip it"


@pytest.mark.parametrize("name", sorted(TERM_VALUES))
def test_the_kernel_of_every_term_with_one_switched_on_is_that_terms_own(name):
    """The missing-physics search fits each candidate with one kernel holding every term (the others off):
    it must fly the candidate's kernel's flight."""
    from bayes_disc.physics.terms import TERMS
    every = tuple(TERMS.values())
    ext = []
    for term in every:
        ext += TERM_VALUES[term.id] if term.id == name else [p.off_value for p in term.parameters]
    y0 = _state(pqr=(4.0, -3.0, 50.0))
    t = np.arange(121) / 120.0
    shared = simulate(y0, HUMMEL, t, marker_body=MARKERS, terms=every, extension=ext)
    own = simulate(y0, HUMMEL, t, marker_body=MARKERS, terms=get_terms([name]), extension=TERM_VALUES[name])
    assert shared.status[0] == 0 and np.abs(shared.markers - own.markers).max() < 1e-9


def test_ground_effect_acts_near_the_ground_only():
    """Extra lift e^(−z/d): a disc skimming at 0.3 m rises against the base model; at 3 m it barely differs."""
    (term,) = get_terms(["ground_effect"])
    t = np.arange(61) / 120.0
    rise = []
    for z0 in (0.3, 3.0):
        y0 = _state(pqr=(0.0, 0.0, 50.0))
        y0[2] = z0
        base = simulate(y0, HUMMEL, t, marker_body=MARKERS)
        on = simulate(y0, HUMMEL, t, marker_body=MARKERS, terms=(term,), extension=[0.4, 0.0, 0.0])
        rise.append(on.markers[0, -1, :, 2].mean() - base.markers[0, -1, :, 2].mean())
    assert rise[0] > 0.005 and abs(rise[1]) < 0.1 * rise[0], rise


def test_terms_change_the_flight():
    y0 = _state()
    t = np.arange(121) / 120.0
    base = simulate(y0, HUMMEL, t)
    side = simulate(y0, HUMMEL, t, terms=get_terms(["side_force"]), extension=[0.5, 1.0])
    off = simulate(y0, HUMMEL, t, terms=get_terms(["side_force"]), extension=[0.0, 1.0])
    assert np.abs(off.states - base.states).max() < 1e-12
    # positive spin (r > 0) pushes to the right: −y in the world frame
    assert side.states[0, -1, 1] < base.states[0, -1, 1] - 0.01


def test_wild_parameters_return_flags_not_nan():
    t = np.arange(241) / 120.0
    good = _state()
    lanes = np.tile(good, (6, 1))
    coef = np.tile(HUMMEL, (6, 1))
    coef[1] *= 1e6                       # absurd coefficients
    lanes[2, 10:13] = [1e5, 0, 1e5]      # tumbling far beyond any throw
    lanes[3, 3:6] = 0.0                  # dropped from rest: falls, stalls
    coef[4, 0] = np.nan                  # NaN parameter
    lanes[5, 3:6] = [1e-9, 0, 0]         # speed → 0
    tr = simulate(lanes, coef, t, marker_body=MARKERS)
    assert tr.status[0] == 0
    assert tr.status[1] != 0 and tr.status[2] != 0 and tr.status[4] != 0
    for b in range(6):
        if tr.status[b] == 0:
            assert np.all(np.isfinite(tr.markers[b])), f"lane {b} ok but not finite"
        else:
            assert np.all(np.isnan(tr.markers[b])), f"lane {b} failed but not NaN"
    solo = simulate(good, HUMMEL, t, marker_body=MARKERS)
    assert np.abs(solo.markers[0] - tr.markers[0]).max() < 1e-7


def test_flight_conditions_match_the_model_with_and_without_wind():
    """α, speed and p, q, r of physics.conditions equal those of the equations' forces (wind included)."""
    from bayes_disc.physics.conditions import flight_conditions
    from bayes_disc.physics.equations import aerodynamic_loads
    from bayes_disc.physics.frames import angle_of_attack
    from bayes_disc.physics.terms import TERMS
    rng = np.random.default_rng(5)
    times = np.linspace(0.0, 1.0, 6)
    states = np.stack([_state(speed=s) for s in (10.0, 13.0, 16.0, 12.0, 14.0, 11.0)])
    states[:, 6:10] = states[:, 6:10] + rng.normal(0, 0.05, (6, 4))
    coef, disc, env = literature_coefficients("hummel2002"), Disc(), Environment()
    wind = np.array([-3.0, 2.0, 0.5])
    terms = (TERMS["side_force"], TERMS["wind"])
    ext = np.concatenate([[0.1, 1.0], wind, [0.0, 0.0]])
    cond = flight_conditions(states[None], times, terms, ext)
    no_wind = flight_conditions(states, times)
    for i, y in enumerate(states):
        loads = aerodynamic_loads(y, coef, disc, env, terms, ext, times[i])
        assert cond.alpha[0, i] == pytest.approx(loads.alpha, abs=1e-13)
        assert cond.speed[0, i] == pytest.approx(loads.speed, rel=1e-13)
        np.testing.assert_allclose(cond.pqr[0, i], loads.pqr, atol=1e-12)
    # the wind matters here, and without it the old definition is recovered
    assert np.max(np.abs(cond.alpha - no_wind.alpha)) > 0.02
    np.testing.assert_allclose(no_wind.alpha[0], angle_of_attack(states[:, 3:6], states[:, 6:10]), atol=1e-14)
    np.testing.assert_allclose(cond.alpha[0], angle_of_attack(states[:, 3:6], states[:, 6:10], wind), atol=1e-14)


def test_kernel_rhs_template_equals_the_readable_equations():
    """physics.rhs.rhs (the kernel's right-hand side, run here as plain Python) = equations.state_derivative."""
    from bayes_disc.physics import rhs
    from bayes_disc.physics.equations import state_derivative
    coef, disc, env = literature_coefficients("hummel2002"), Disc(), Environment()
    m, Ia, Id, d, A, rho = disc.mass, disc.Ia, disc.Id, disc.diameter, disc.area, env.rho
    scale = np.r_[[0.5 * rho * A / m] * 4, [0.5 * rho * A * d / Id] * 5, 0.5 * rho * A * d / Ia]
    cf = tuple(coef.as_array() * scale)
    kd = (env.g, (Id - Ia) / Id, 1.0 / m, 1.0 / Id, 1.0 / Ia, m, A, d, rho)
    for y in (_state(), _state(speed=9.0, pitch=0.5, roll=-0.3, pqr=(-4.0, 6.0, 80.0))):
        got = np.array(rhs.rhs(0.0, tuple(y), cf, (0.0,), kd))
        want = state_derivative(0.0, y, coef, disc, env)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_one_extension_vector_serves_a_whole_batch():
    """extension (n_ext,) or None (off values) applies to every lane of a batch ((B, n) or (n,))."""
    terms = get_terms(["wind", "side_force"])
    y0 = np.stack([_state(speed=s) for s in (11.0, 13.0, 15.0)])
    t = np.arange(0.0, 0.3, 1 / 120)
    ext = np.array([1.0, -2.0, 0.3, 0.0, 0.0, 0.05, 1.0])
    batch = simulate(y0, HUMMEL, t, terms=terms, extension=ext)
    off = simulate(y0, HUMMEL, t, terms=terms)
    for b in range(3):
        np.testing.assert_array_equal(batch.states[b], simulate(y0[b], HUMMEL, t, terms=terms, extension=ext).states[0])
        np.testing.assert_array_equal(off.states[b], simulate(y0[b], HUMMEL, t, terms=terms).states[0])
        np.testing.assert_allclose(off.states[b], simulate(y0[b], HUMMEL, t).states[0], rtol=0, atol=1e-12)
    assert np.abs(batch.states[:, -1, :3] - off.states[:, -1, :3]).max() > 1e-3    # the parameters act


def _packed_share(terms) -> float:
    """Share of packed (…pd) among the double-precision arithmetic instructions (add, sub, mul, div, fused
    multiply-add) of a 4-lane kernel's compiled ``integrate``, compiled in memory so that its assembly is kept."""
    import re
    from bayes_disc.physics.codegen import kernel_source
    from bayes_disc.physics.kernel import LANES_SMALL
    from bayes_disc.physics.kernel_cache import compile_in_memory
    from bayes_disc.physics.simulator import _constants
    from bayes_disc.physics.tableaux import DEFAULT_METHOD, get_tableau
    f = compile_in_memory(kernel_source(terms, get_tableau(DEFAULT_METHOD), LANES_SMALL, cache=False))
    ext = np.array([[p.off_value for t in terms for p in t.parameters]])
    f(_state()[None], HUMMEL[None], ext, _constants(Disc(), Environment()), 0.0, np.array([0.0, 0.1]), MARKERS,
      1.7, 1e4, 1e3, 0.0, 2.0, np.zeros((1, 0, 13)), np.zeros((1, 0, 3, 3)), np.zeros(1, np.int64))
    asm = f.inspect_asm(f.signatures[0])
    ops = re.findall(r"^\s*v?(?:add|sub|mul|div|f[n]?m(?:add|sub)\d*)([ps]d)\b", asm, flags=re.MULTILINE)
    return ops.count("pd") / max(len(ops), 1)


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"),
                    reason="counts x86-64 packed and scalar double-precision instructions")
def test_a_kernel_carrying_a_term_is_vectorised_like_the_base_kernel():
    """LLVM vectorises the base kernel's loop over the lanes of a group; a term's hooks must not stop it (a hook
    that reads an array inside that loop does, and the kernel then runs several times slower): the packed share
    of the compiled integrator's double-precision arithmetic, with a term, is at least half the base kernel's."""
    base = _packed_share(())
    term = _packed_share(get_terms(["disc_asymmetry"]))
    assert base > 0.5, base
    assert term > 0.5 * base, (term, base)
