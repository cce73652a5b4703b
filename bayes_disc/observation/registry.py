"""One registry of the model's pluggable units: physics terms, data explanations and observation models.

Every unit has an id (the one the configuration uses), a kind, a title, its equations and its parameters.
Physics terms (:mod:`bayes_disc.physics.terms`) change the flight; data explanations
(:mod:`.explanations`) change how recordings relate to the flight; observation models (:mod:`.models`)
predict one kind of recording. Config readers, synth, the parameter layout, the missing-physics search and
the report ask this module; an unknown id is an error naming the known ones.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..physics import TERMS, Term, TermParameter
from ..physics.discrepancy import DISCREPANCY
from .explanations import EXPLANATIONS, DataExplanation
from .models import MarkerPositions

PHYSICS_TERM = "physics term"
DATA_EXPLANATION = "data explanation"
OBSERVATION_MODEL = "observation model"
#: a correction learned by ``diagnose`` (:mod:`bayes_disc.physics.discrepancy`): a physics term, but neither a
#: missing-physics candidate nor something a run's configuration can ask for
LEARNED = "learned correction"

#: observation-model classes by id
OBSERVATION_MODELS = {m.id: m for m in (MarkerPositions,)}


@dataclass(frozen=True)
class Unit:
    """A registered unit: id, kind, title, equations and the object itself (Term, DataExplanation or an
    ObservationModel class)."""

    id: str
    kind: str
    title: str
    equations: str
    obj: object

    def parameters(self, marker_ids: tuple = ()) -> tuple[TermParameter, ...]:
        """The unit's parameters shared by all flights (explanations depend on the marker ids)."""
        if self.kind in (PHYSICS_TERM, LEARNED):
            return self.obj.parameters
        if self.kind == DATA_EXPLANATION:
            return self.obj.parameters_for(tuple(marker_ids))
        return ()

    def parameter_names(self, marker_ids: tuple = ()) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters(marker_ids))


UNITS: dict[str, Unit] = {
    **{t.id: Unit(t.id, PHYSICS_TERM, t.title, t.equations, t) for t in TERMS.values()},
    **{e.id: Unit(e.id, DATA_EXPLANATION, e.title, e.equations, e) for e in EXPLANATIONS.values()},
    **{m.id: Unit(m.id, OBSERVATION_MODEL, m.title, m.equations, m) for m in OBSERVATION_MODELS.values()},
    DISCREPANCY.id: Unit(DISCREPANCY.id, LEARNED, DISCREPANCY.title, DISCREPANCY.equations, DISCREPANCY),
}

#: ids a model can be extended by (the missing-physics candidates), in registry order
MODEL_EXTENSIONS: tuple[str, ...] = tuple(i for i, u in UNITS.items() if u.kind in (PHYSICS_TERM, DATA_EXPLANATION))


def unit(uid: str, kinds: tuple[str, ...] | None = None) -> Unit:
    """The unit ``uid``; KeyError naming the known ids (of ``kinds``, if given) when there is none."""
    u = UNITS.get(uid)
    if u is None or (kinds is not None and u.kind not in kinds):
        known = sorted(i for i, v in UNITS.items() if kinds is None or v.kind in kinds)
        raise KeyError(f"unknown {' or '.join(kinds) if kinds else 'unit'} {uid!r}; known: {known}")
    return u


def split_extensions(ids) -> tuple[tuple[Term, ...], tuple[DataExplanation, ...]]:
    """Model-extension ids → (physics terms, data explanations), each in the order given (the learned
    discrepancy counts as a physics term)."""
    units = [unit(i, (PHYSICS_TERM, DATA_EXPLANATION, LEARNED)) for i in ids]
    return (tuple(u.obj for u in units if u.kind in (PHYSICS_TERM, LEARNED)),
            tuple(u.obj for u in units if u.kind == DATA_EXPLANATION))
