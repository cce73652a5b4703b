"""Progress of a sampling run toward convergence: one line of figures and the terminal bar (or log lines).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

from ..model.config import SamplerSettings
from .stopping import warm_up_steps

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Progress:
    """Where the ensembles stand toward the stopping rule, as shown on the progress bar.

    Attributes
    ----------
    steps : int
        Steps done by every ensemble.
    cap : int
        The ``max_steps`` cap (shown, never used as a measure of progress).
    fraction : float
        Progress toward convergence in [0, 1] (:func:`convergence_fraction`); 0 during warm-up.
    verdict : dict or None
        The last convergence check (:func:`convergence`), None before the first.
    """

    steps: int
    cap: int
    fraction: float
    verdict: dict | None

    def describe(self, settings: SamplerSettings) -> str:
        """One line: step counter with the cap, and each criterion's figure beside its target."""
        head = f"step {self.steps} (cap {self.cap})"
        if self.verdict is None:
            return f"{head}, warm-up until step {warm_up_steps(settings)}"
        v = self.verdict
        return (f"{head}, R-hat {v['rhat_max']:.3f} (< {settings.rhat:g}), ESS {v['ess_min_coef']:.0f} "
                f"(≥ {settings.ess:g}), N/τ {v['n_over_tau']:.1f} (≥ {settings.n_tau:g})")


class _Bar:
    """The convergence bar (tqdm; none when ``progress`` is False or stderr is not a terminal), and the
    same figures as log lines when there is no bar."""

    FORMAT = "{desc}: {percentage:3.0f}% of the way to convergence |{bar}|{postfix} [{elapsed}]"

    def __init__(self, settings: SamplerSettings, progress: bool):
        from tqdm import tqdm
        self.settings = settings
        self.bar = tqdm(total=100, desc="sampling", bar_format=self.FORMAT, leave=False,
                        disable=None if progress else True)

    @property
    def shown(self) -> bool:
        return not self.bar.disable

    def show(self, state: Progress, checked: bool) -> None:
        line = state.describe(self.settings)
        if self.shown:
            self.bar.n = int(round(100 * state.fraction))
            self.bar.set_postfix_str(line, refresh=False)
            self.bar.refresh()
        if checked:
            logger.log(logging.DEBUG if self.shown else logging.INFO,
                       f"convergence check: {line}; {100 * state.fraction:.0f}% of the way")

    def close(self) -> None:
        self.bar.close()
