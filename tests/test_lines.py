"""Oscillations left in the residuals (bayes_disc.diagnostics.lines): a sinusoid in noise is found with its
frequency, amplitude and share; white noise and too-slow changes are not reported; the spin's multiple and the
words."""
import numpy as np
import pytest

from bayes_disc.diagnostics.diagnosis_words import lines_words
from bayes_disc.diagnostics.lines import LINE_SHARE, MIN_CYCLES, flight_lines, residual_lines, strongest_line
from bayes_disc.diagnostics.residuals import FlightResiduals
from bayes_disc.observation.models.base import ResidualSeries

P = 0.0122                      # a logger's row period [s]
T = np.arange(300) * P          # 3.66 s


@pytest.mark.parametrize("f, amp, sigma", [(0.8, 0.35, 0.2), (8.3, 0.5, 0.3), (25.0, 1.0, 0.1)])
def test_a_sinusoid_in_white_noise_is_found(f, amp, sigma):
    rng = np.random.default_rng(3)
    x = amp * np.cos(2 * np.pi * f * T + 1.1) + 0.7 + sigma * rng.standard_normal(T.size)
    line = strongest_line(T, x)
    assert line["frequency_hz"] == pytest.approx(f, abs=0.5 / T[-1])
    assert line["amplitude"] == pytest.approx(amp, rel=0.1)
    expected = amp ** 2 / 2 / (amp ** 2 / 2 + sigma ** 2)
    assert line["share"] == pytest.approx(expected, abs=0.05)
    assert line["cycles"] == pytest.approx(f * T[-1], rel=0.05)


def test_white_noise_carries_no_line():
    rng = np.random.default_rng(4)
    shares = [strongest_line(T, rng.standard_normal(T.size))["share"] for _ in range(50)]
    assert max(shares) < LINE_SHARE / 2
    # about 2 ln(n/2)/n for n samples (module docstring)
    assert np.median(shares) == pytest.approx(2 * np.log(T.size / 2) / T.size, rel=0.5)


@pytest.mark.parametrize("trend", [lambda t: np.sin(2 * np.pi * t / t[-1]), lambda t: (t / t[-1]) ** 2,
                                   lambda t: np.exp(-3 * t)])
def test_a_change_slower_than_two_cycles_is_not_a_line(trend):
    """One cycle in the span, a parabola, a decay: trends. The grid starts at MIN_CYCLES cycles and a line must be
    a peak inside it, so none is found, or only a faster one that explains little."""
    rng = np.random.default_rng(7)
    line = strongest_line(T, trend(T) + 0.01 * rng.standard_normal(T.size))
    assert line is None or (line["cycles"] > MIN_CYCLES and line["share"] < LINE_SHARE)


def test_gaps_are_left_out_and_short_series_give_nothing():
    rng = np.random.default_rng(5)
    x = np.cos(2 * np.pi * 3.0 * T) + 0.1 * rng.standard_normal(T.size)
    x[40:90] = np.nan
    assert strongest_line(T, x)["frequency_hz"] == pytest.approx(3.0, abs=0.5 / T[-1])
    assert strongest_line(T[:6], x[:6]) is None
    assert strongest_line(T, np.zeros(T.size)) is None


def _flight(name, spin, series):
    n = T.size
    part = ResidualSeries(times=T, series=series, unit_se={k: np.ones(n) for k in series},
                          groups={k: 0 for k in series}, units={k: "m/s²" for k in series},
                          covariates={"spin": np.full(n, spin), "time": T}, primary=tuple(series),
                          group_channels=(("acc", "m/s²"),))
    return FlightResiduals(name, [part], ("imu",), (0,))


def test_lines_of_a_flight_carry_the_spin_multiple_and_are_ranked_by_share():
    rng = np.random.default_rng(6)
    spin = -2 * np.pi * 9.0                                             # 9 rev/s, either sense
    series = {"acc_z": 0.4 * np.cos(2 * np.pi * 0.77 * T) + 0.1 * rng.standard_normal(T.size),
              "acc_x": 0.2 * np.cos(2 * np.pi * 9.0 * T) + 0.1 * rng.standard_normal(T.size),
              "acc_y": 0.2 * rng.standard_normal(T.size)}
    found = flight_lines(_flight("a", spin, series))
    assert list(found) == ["acc_z", "acc_x"]                             # acc_y: noise, not reported
    assert found["acc_z"]["per_spin"] == pytest.approx(0.77 / 9.0, abs=0.01)
    assert found["acc_x"]["per_spin"] == pytest.approx(1.0, abs=0.02)
    assert found["acc_z"]["unit"] == "m/s²"
    quiet = _flight("b", spin, {"acc_y": series["acc_y"]})
    assert residual_lines([_flight("a", spin, series), quiet]).keys() == {"a"}


def test_lines_in_words():
    text = lines_words({"lines": {"001": {"acc_z": {"frequency_hz": 0.77, "amplitude": 0.36, "share": 0.6,
                                                     "cycles": 2.8, "unit": "m/s²", "per_spin": 0.086}}}})
    assert text == ["Oscillations left in flight 001: accelerometer z (disc normal) 0.36 m/s² at 0.77 Hz "
                    "(0.086 × spin, 60 % of its residual)."]
    assert lines_words({"lines": None}) == []
