"""The wobble decomposition (bayes_disc.diagnostics.wobble): known phasors recovered, the simulated rigid
disc's nutation rate and decay measured as the linearised Euler equations predict, the words of a
data–model comparison, and the report's figure."""
from __future__ import annotations

import numpy as np
import pytest

from bayes_disc.diagnostics.wobble import (DECAY_SPANS, rigid_kappa, rigid_nutation, spin_phase, throw_wobble,
                                           wobble_summary, wobble_track, wobble_words)
from bayes_disc.observation.inertial_synth import LoggerSpec, logger_readings
from bayes_disc.physics import Coefficients, Disc, Environment
from bayes_disc.physics.frames import matrix_to_quat

PERIOD = 0.0125                       # s, the flatball loggers' order of magnitude
R_LEVEL = np.diag([1.0, -1.0, -1.0])  # level right-side-up disc, b3 down


def synthetic_gyro(kappa, decay=0.0, amplitude=4.0, space_fixed=0.15, constant=0.4 * np.exp(0.7j), noise=0.2,
                   duration=3.0, seed=0):
    """(t, gyro (n, 3)) of a nutation phasor at κ(t) × spin decaying at ``decay`` [1/s], a space-fixed phasor, a
    constant and white noise [rad/s]; the spin slows from 60 to 51 rad/s. ``kappa``: float or callable of t."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, PERIOD)
    r = 60.0 - 3.0 * t
    phi = spin_phase(t, r)
    k = kappa(t) if callable(kappa) else np.full(t.size, kappa)
    nut_phase = spin_phase(t, k * r)                     # ∫ κ r dt
    z = (amplitude * np.exp(-decay * t) * np.exp(1j * (nut_phase + 0.3)) + space_fixed * np.exp(-1j * (phi - 1.1))
         + constant + noise * (rng.normal(size=t.size) + 1j * rng.normal(size=t.size)))
    return t, np.c_[z.real, z.imag, r + 0.01 * rng.normal(size=t.size)]


def test_known_phasors_recovered():
    """κ within five standard errors (σ_κ ≈ 0.01 rad/s / A: phase noise 0.2/A rad per sample, ~20 samples and
    ~15 rad of spin phase per window) plus 0.002, the nutation amplitude within 3 % (the window's averaging of
    the exponential: λ²T²/24 ≈ 2 %) plus four standard errors (0.18 rad/s), decay within 0.3 /s, the medians of
    the space-fixed and sensor-fixed amplitudes within 0.05 rad/s."""
    kappa, decay, amp = 0.9, 3.0, 4.0
    t, g = synthetic_gyro(kappa, decay, amp, duration=1.2)
    track = wobble_track(t, g)
    assert track.times.size > 15
    true_amp = amp * np.exp(-decay * track.times)
    ok = np.isfinite(track.kappa)
    assert ok[:8].all()
    assert np.all(np.abs(track.kappa[ok] - kappa) < 0.05 / true_amp[ok] + 0.002)
    assert np.all(np.abs(np.abs(track.nutation) - true_amp) < 0.03 * true_amp + 0.18)
    s = wobble_summary(track)
    for span in ("early", "middle"):        # medians over windows; one window's standard error ≈ 0.28/√20 rad/s
        assert s["space_fixed_rad_s"][span] == pytest.approx(0.15, abs=0.05)
        assert s["constant_rad_s"][span] == pytest.approx(0.4, abs=0.05)
    assert np.abs(np.median(track.constant) - 0.4 * np.exp(0.7j)) < 0.05
    assert s["decay_per_s"]["early"] == pytest.approx(decay, abs=0.3)
    assert s["decay_per_s"]["late"] == pytest.approx(decay, abs=0.3)
    assert s["constant_tilt_deg"] == pytest.approx(np.degrees(0.4 / np.median(track.spin)), rel=0.13)


def test_growth_and_drift_recovered():
    """A growing nutation (negative decay rate) whose κ rises from 0.84 to 0.97 over 3 s is followed window by
    window (κ within 0.01 of κ at the window centre)."""
    def kappa(t):
        return 0.84 + 0.13 * t / 3.0
    t, g = synthetic_gyro(kappa, decay=-0.5, amplitude=2.0, duration=3.0, seed=3)
    track = wobble_track(t, g)
    assert np.all(np.abs(track.kappa - kappa(track.times)) < 0.01)
    s = wobble_summary(track)
    assert s["decay_per_s"]["late"] == pytest.approx(-0.5, abs=0.2)
    assert s["kappa"]["late"] - s["kappa"]["early"] > 0.08


def test_unresolved_nutation_has_no_kappa():
    """Where the nutation has decayed into the noise, κ is not reported (NaN): a span without a resolved window
    has no κ, the early span keeps its finite one."""
    t, g = synthetic_gyro(0.9, decay=6.0, amplitude=3.0, duration=2.5, seed=5)
    track = wobble_track(t, g)
    late = track.times > 1.8
    assert np.all(np.isnan(track.kappa[late]))
    assert wobble_summary(track)["kappa"]["early"] == pytest.approx(0.9, abs=0.02)   # A ≈ 1 rad/s: σ_κ ≈ 0.01
    assert wobble_summary(track)["kappa"]["late"] is None


def _simulated_gyro(coefficients, spin, tilt=(0.004, -0.003), duration=1.5, speed=20.0):
    """A simulated wobbling throw without gravity's effect on the path (g → 0, no lift or drag): level disc
    flying at ``speed`` [m/s] with body rates (3, −2, spin) [rad/s] at release, read by a tilted logger."""
    disc, env = Disc(), Environment(g=1e-9)
    y0 = np.r_[0.0, 0.0, 1.0, R_LEVEL @ np.array([speed, 0.0, 0.0]), matrix_to_quat(R_LEVEL), 3.0, -2.0, spin]
    spec = LoggerSpec(period=PERIOD, tilt=tilt)
    n = int(duration / PERIOD) + 1
    gyro, _, _, _ = logger_readings(y0, coefficients, n, spec, disc, env)
    qad = 0.5 * env.rho * speed ** 2 * disc.area * disc.diameter
    return np.arange(n) * PERIOD, gyro, disc, qad


@pytest.mark.parametrize("spin", [60.0, -60.0])
def test_simulated_torque_free_throw_turns_at_rigid_kappa(spin):
    """Without aerodynamic moments the body's transverse ω turns at κ₀ = (Ia − Id)/Id of the spin, its amplitude
    holds, and the sensor-fixed part is the mount tilt |ε| × |r|."""
    t, gyro, disc, _ = _simulated_gyro(Coefficients(*[0.0] * 10), spin)
    track = wobble_track(t, gyro)
    k0 = (disc.Ia - disc.Id) / disc.Id
    assert rigid_kappa(disc.Ia, disc.Id, spin) == pytest.approx(k0)
    np.testing.assert_allclose(track.kappa, k0, atol=0.001)
    s = wobble_summary(track)
    assert abs(s["decay_per_s"]["early"]) < 0.05
    np.testing.assert_allclose(np.abs(track.constant), np.hypot(0.004, -0.003) * abs(spin), rtol=0.03)


@pytest.mark.parametrize("cma, cmq, crp", [(0.1, 0.003, -0.004), (-0.1, -0.004, 0.002)])
def test_simulated_throw_with_moments_matches_linear_nutation(cma, cmq, crp):
    """With a pitch stiffness (C_Mα) and pitch and roll damping (C_Mq, C_Rp) the measured κ and decay are the
    roots of the linearised Euler equations (rigid_nutation), and differ from the torque-free disc's."""
    spin = 60.0
    t, gyro, disc, qad = _simulated_gyro(Coefficients(0, 0, 0, 0, 0, cma, cmq, 0, crp, 0), spin)
    kappa, lam = rigid_nutation(disc.Ia, disc.Id, spin, -qad * cma, qad * crp, qad * cmq)
    assert abs(kappa - (disc.Ia - disc.Id) / disc.Id) > 0.015
    track = wobble_track(t, gyro)
    np.testing.assert_allclose(track.kappa, kappa, atol=0.002)
    s = wobble_summary(track)
    assert s["decay_per_s"]["early"] == pytest.approx(lam, abs=0.1)
    assert s["decay_per_s"]["late"] == pytest.approx(lam, abs=0.1)


def test_pitch_stiffness_alone_matches_closed_form():
    """With k only, the cubic of rigid_nutation gives the closed form κ = (Ia/Id)√(1 + Id k/(Ia² r²)) − 1."""
    disc = Disc()
    for k in (-1.5, 0.0, 1.5):
        kappa, lam = rigid_nutation(disc.Ia, disc.Id, 55.0, k)
        assert kappa == pytest.approx(rigid_kappa(disc.Ia, disc.Id, 55.0, k), abs=1e-9)
        assert lam == pytest.approx(0.0, abs=1e-9)


def test_words_name_a_kappa_mismatch():
    """Data drifting from κ 0.84 to 0.97 against a model fixed at 0.93: the words name κ and both behaviours."""
    t, data = synthetic_gyro(lambda t: 0.84 + 0.13 * t / 3.0, decay=0.0, amplitude=2.0, seed=1)
    _, model = synthetic_gyro(0.93, decay=0.0, amplitude=2.0, noise=0.0, seed=2)
    rec = throw_wobble(t, data, model, Ia=Disc().Ia, Id=Disc().Id)
    assert "kappa" in rec["mismatch"]
    text = wobble_words("T", rec)
    assert "rising" in text and "fixed κ 0.93" in text and "matches" not in text


def test_words_name_a_decay_mismatch():
    """Data decaying at 4 /s early against an undamped model: the words give both rates."""
    t, data = synthetic_gyro(0.9, decay=4.0, amplitude=4.0, duration=1.5, seed=1)
    _, model = synthetic_gyro(0.9, decay=0.0, amplitude=4.0 * np.exp(-4.0 * 0.25), noise=0.0, duration=1.5)
    rec = throw_wobble(t, data, model, Ia=Disc().Ia, Id=Disc().Id)
    assert "decay_early" in rec["mismatch"] and "kappa" not in rec["mismatch"]
    text = wobble_words("T", rec)
    assert f"in the first {DECAY_SPANS['early'][1]:.2f} s" in text and "decays at 4." in text


def test_words_say_nothing_is_wrong_when_model_and_data_agree():
    """The model reproducing the data's wobble (same components, other noise): no mismatch, and the words say
    that the model's wobble matches."""
    t, data = synthetic_gyro(0.9, decay=2.0, amplitude=4.0, seed=1)
    _, model = synthetic_gyro(0.9, decay=2.0, amplitude=4.0, noise=0.0, seed=2)
    rec = throw_wobble(t, data, model, Ia=Disc().Ia, Id=Disc().Id)
    assert rec["mismatch"] == []
    assert "matches" in wobble_words("T", rec)


def test_wobble_figure_draws_every_throw():
    """The report's figure: two rows (κ, amplitudes) and one column per throw, data and model drawn."""
    from bayes_disc.diagnostics.diagnosis import _finite
    from bayes_disc.report.figures import wobble_figure
    t, data = synthetic_gyro(0.9, decay=2.0, amplitude=4.0, duration=1.0)
    _, model = synthetic_gyro(0.93, decay=0.5, amplitude=4.0, noise=0.0, duration=1.0)
    rec = _finite(throw_wobble(t, data, model, Ia=Disc().Ia, Id=Disc().Id))
    fig = wobble_figure({"a": rec, "b": rec})
    axes = fig.get_axes()
    assert len(axes) == 4
    assert all(len(ax.get_lines()) >= 2 for ax in axes)
