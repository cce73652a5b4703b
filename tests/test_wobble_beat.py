"""The late wobble as a beat of a spin-locked and a free nutation (bayes_disc.diagnostics.wobble_beat): known
phasors recovered in either spin sense, a single nutation not split in two, the simulated torque-free disc's
free nutation found at its rigid κ, and the words of a data–model comparison."""
from __future__ import annotations

import numpy as np
import pytest

from bayes_disc.diagnostics.wobble import spin_phase, throw_wobble, wobble_words
from bayes_disc.diagnostics.wobble_beat import START_S, beat_fit, beat_words, late_beat
from bayes_disc.physics import Coefficients, Disc

from test_wobble import PERIOD, _simulated_gyro


def beat_gyro(kappa_free=0.95, free=0.5, locked=0.4, free_decay=0.0, locked_decay=0.5, constant=0.35 * np.exp(0.4j),
              noise=0.1, spin0=58.0, duration=3.5, seed=0):
    """(t, gyro (n, 3)): a constant, a nutation locked to the spin and a free one at ``kappa_free`` × spin, each
    decaying at its rate [1/s] from release, plus white noise [rad/s]; the spin slows by 3 rad/s per second
    (its sign is the spin's sense: both nutations turn with it). Amplitudes are given at release."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, PERIOD)
    r = np.sign(spin0) * (abs(spin0) - 3.0 * t)
    phi = spin_phase(t, r)
    z = (constant + locked * np.exp(-locked_decay * t) * np.exp(1j * (phi + 0.2))
         + free * np.exp(-free_decay * t) * np.exp(1j * (kappa_free * phi - 1.0)))
    z = z + noise * (rng.normal(size=t.size) + 1j * rng.normal(size=t.size))
    return t, np.c_[z.real, z.imag, r + 0.01 * rng.normal(size=t.size)]


def _at_centre(amplitude, decay, rec):
    """A phasor's amplitude at release carried to the late span's centre."""
    return amplitude * np.exp(-decay * 0.5 * sum(rec["span_s"]))


@pytest.mark.parametrize("spin0", [58.0, -58.0])
def test_known_beat_recovered(spin0):
    """κ_F within 0.002 (a 2.5 s span turns ≈ 140 rad of spin phase: σ_κ ≈ 0.1/(0.4 × 140 × √200) ≈ 1e-4),
    the amplitudes at the span's centre within 0.03 rad/s, the decay rates within 0.15 /s, both nutations
    resolved, the RMS left at the noise (0.1 rad/s per component) and the beat period 2π/((1 − κ_F)|r̄|)."""
    t, g = beat_gyro(spin0=spin0, free_decay=-0.2)
    rec = late_beat(t, g, spin_phase(t, g[:, 2]))
    assert rec["span_s"][0] == pytest.approx(START_S, abs=PERIOD)
    assert rec["kappa_free"] == pytest.approx(0.95, abs=0.002)
    assert rec["free_rad_s"] == pytest.approx(_at_centre(0.5, -0.2, rec), abs=0.03)
    assert rec["locked_rad_s"] == pytest.approx(_at_centre(0.4, 0.5, rec), abs=0.03)
    assert rec["constant_rad_s"] == pytest.approx(0.35, abs=0.03)
    assert rec["free_decay_per_s"] == pytest.approx(-0.2, abs=0.15)
    assert rec["locked_decay_per_s"] == pytest.approx(0.5, abs=0.15)
    assert rec["free_resolved"] and rec["locked_resolved"]
    assert rec["rms_rad_s"] == pytest.approx(0.1, abs=0.01)
    assert rec["free_share"] > 0.8
    spin = abs(np.mean(g[t >= START_S, 2]))
    assert rec["beat_period_s"] == pytest.approx(2 * np.pi / (0.05 * spin), rel=0.05)


def test_locked_nutation_alone_is_not_split():
    """With no free nutation the free phasor is not resolved and takes nothing from the locked one."""
    t, g = beat_gyro(free=0.0)
    rec = late_beat(t, g, spin_phase(t, g[:, 2]))
    assert not rec["free_resolved"] and rec["locked_resolved"]
    assert rec["locked_rad_s"] == pytest.approx(_at_centre(0.4, 0.5, rec), abs=0.03)
    assert rec["free_share"] < 0.05


def test_short_flight_has_no_late_beat():
    """A throw that ends before a late span of MIN_SPAN_S: no record; a span too short for half a beat: none."""
    t, g = beat_gyro(duration=1.6)
    assert late_beat(t, g, spin_phase(t, g[:, 2])) is None
    m = t < 0.15                    # 12 samples, 0.14 s: half a beat needs κ_F below 0.61
    assert beat_fit(t[m], g[m, 0] + 1j * g[m, 1], spin_phase(t, g[:, 2])[m], 58.0) is None


def test_simulated_torque_free_disc_is_one_free_nutation():
    """The simulated disc without moments: one free nutation at κ₀ = (Ia − Id)/Id that neither decays nor grows,
    and nothing locked to the spin."""
    t, gyro, disc, _ = _simulated_gyro(Coefficients(*[0.0] * 10), 60.0, duration=2.6)
    rec = late_beat(t, gyro, spin_phase(t, gyro[:, 2]))
    assert rec["kappa_free"] == pytest.approx((disc.Ia - disc.Id) / disc.Id, abs=0.001)
    assert rec["free_resolved"] and not rec["locked_resolved"]
    assert abs(rec["free_decay_per_s"]) < 0.05
    assert rec["rms_rad_s"] < 0.01


def test_words_say_the_model_lacks_the_free_wobble():
    """Data that beat against a model with the locked nutation only: the words give the data's free κ and the
    beat period, and say that the model lacks the free wobble; the throw's wobble words carry the sentence."""
    t, data = beat_gyro(seed=1)
    _, model = beat_gyro(free=0.0, noise=0.0, seed=2)
    rec = throw_wobble(t, data, model, Ia=Disc().Ia, Id=Disc().Id)
    d, m = rec["beat"]["data"], rec["beat"]["model"]
    text = beat_words(d, m)
    assert f"κ {d['kappa_free']:.3f}" in text and f"every {d['beat_period_s']:.1f} s" in text
    assert "lacks the free wobble" in text and "no free wobble" in text
    assert "free_late" in rec["mismatch"]
    assert text in wobble_words("T", rec) and "matches" not in wobble_words("T", rec)


def test_words_do_not_name_a_missing_free_wobble_when_the_model_has_it():
    t, data = beat_gyro(seed=1)
    _, model = beat_gyro(noise=0.0, seed=2)
    rec = throw_wobble(t, data, model, Ia=Disc().Ia, Id=Disc().Id)
    assert "lacks" not in beat_words(rec["beat"]["data"], rec["beat"]["model"])
    assert "free_late" not in rec["mismatch"]


def test_simulated_disc_asymmetry_is_a_beat_of_forced_and_free_nutation():
    """A disc with an aerodynamic asymmetry (no other aerodynamics, almost no gravity: Q and r constant),
    released without wobble: W = a e^{irt} + b e^{iκ₀rt} with b = −a and a = C Q A d / (i Id (1 − κ₀) r)
    (tests/test_wobble_terms.py). Its late span is a beat of a locked nutation of |a| and a free one of |a| at
    κ₀, neither decaying, every 2π/((1 − κ₀) r)."""
    from bayes_disc.physics import Environment, get_terms, simulate
    from test_wobble_terms import ZERO, _state
    disc, env, r, V, c = Disc(), Environment(g=1e-9), 60.0, 13.0, 0.004 + 0.003j
    times = np.arange(0.0, 3.0, PERIOD)
    tr = simulate(_state(pqr=(0.0, 0.0, r), tilt=(0.0, 0.0), speed=V), ZERO.as_array(), times, env=env,
                  terms=get_terms(["disc_asymmetry"]), extension=np.array([c.real, c.imag]))
    gyro = tr.states[0][:, 10:13]
    kappa = disc.Ia / disc.Id - 1
    a = abs(c) * 0.5 * env.rho * (V ** 2 + 1.0) * disc.area * disc.diameter / (disc.Id * (1 - kappa) * r)
    rec = late_beat(times, gyro, spin_phase(times, gyro[:, 2]))
    assert rec["kappa_free"] == pytest.approx(kappa, abs=0.001)
    assert rec["locked_rad_s"] == pytest.approx(a, rel=0.02) and rec["free_rad_s"] == pytest.approx(a, rel=0.02)
    assert abs(rec["locked_decay_per_s"]) < 0.02 and abs(rec["free_decay_per_s"]) < 0.02
    assert rec["beat_period_s"] == pytest.approx(2 * np.pi / ((1 - kappa) * r), rel=0.01)
    assert rec["rms_rad_s"] < 0.02 * a
