"""A statistical problem described for logs, run files and the report: its flights' recordings and their
marker noise models."""
from __future__ import annotations

from ...observation.models import MarkerPositions


def flight_info(problem) -> dict:
    """Per flight: its recordings (marker samples and points; inertial rows) and their time span."""
    out = {}
    for k, f in enumerate(problem.flights):
        rec = {"file": f.source}
        for c in problem.channels[k]:
            if isinstance(c, MarkerPositions):
                rec.update(samples=int(c.data.times.size), points=int(c.data.n_points),
                           t_start=float(c.data.times[0]), t_end=float(c.data.times[-1]))
            else:
                rec.update(inertial_rows=int(c.n_flight), inertial_values=int(c.group_index.size),
                           rows_since_release=int(c.row_offsets[c.n_flight - 1]))
        out[f.name] = rec
    return out


def noise_info(problem) -> dict:
    """Per marker flight: its noise model (:meth:`~bayes_disc.observation.models.noise.MarkerNoise.describe`:
    ``model``, ``per_point`` (``sigma_m``, ``covariance`` or null), ``reference_sigma_m`` ḡ [m] (σ_f / ḡ is
    the scale factor of the stated per-point errors) and the unit's own parameters)."""
    return {f.name: c.noise.describe() for f, ch in zip(problem.flights, problem.channels) for c in ch
            if isinstance(c, MarkerPositions)}


def noise_words(info: dict) -> str:
    """"flight a: ar1, per-point errors from sigma_m (ḡ = 2.1 mm)" per flight, for the log."""
    out = []
    for name, d in info.items():
        pp = (f", per-point errors from {d['per_point']} (geometric mean {d['reference_sigma_m'] * 1e3:.3g} mm)"
              if d["per_point"] else ", one σ for every point")
        out.append(f"{name}: {d['model']}{pp}")
    return "; ".join(out)


def data_words(problem) -> str:
    """"3 flights, 1200 marker points, 5400 inertial values"."""
    markers = sum(int(c.data.n_points) for ch in problem.channels for c in ch if isinstance(c, MarkerPositions))
    inertial = sum(int(c.group_index.size) for ch in problem.channels for c in ch
                   if not isinstance(c, MarkerPositions))
    words = [f"{problem.n_flights} flights"] + ([f"{markers} marker points"] if markers else []) \
        + ([f"{inertial} inertial values"] if inertial else [])
    return ", ".join(words)
