"""What an optimiser is to the rest of finaldrive: ask/tell of whole batches, maximising.

The study layer, the scheduler and the command line drive every method through :class:`Optimiser`
and know no method's internals. A method is a class that follows the protocol and is registered
under its name (:func:`register`); :func:`restore` rebuilds any of them from its
:meth:`Optimiser.state`. Adding a method is its module, one line in ``finaldrive.engine.optimize``
and its own settings in ``finaldrive.engine.study.space.DESettings.build``.

Each :meth:`Optimiser.tell` ends a round and appends its record to ``history``: ``generation``
(rounds told after the first), ``n_evals`` (evaluations told so far), ``best_f``, ``mean_f`` (the
mean finite fitness of the designs the method keeps) and ``n_failed`` (that round's failures).
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

#: name -> optimiser class (see :func:`register`)
OPTIMISERS: dict[str, type[Optimiser]] = {}


@runtime_checkable
class Optimiser(Protocol):
    """An ask/tell optimiser of whole batches (maximises; NaN fitness is a failed evaluation)."""

    method: ClassVar[str]
    #: the round records (a caller may clear the list once it has kept them)
    history: list[dict[str, Any]]

    @property
    def n_evals(self) -> int:
        """Evaluations told so far."""

    @property
    def generation(self) -> int:
        """Rounds told after the first."""

    @property
    def stop_reason(self) -> str | None:
        """Which stopping rule fired (None while running)."""

    def ask(self) -> np.ndarray:
        """The next batch of rows (n, d) to evaluate; asking again before a tell returns the same."""

    def tell(self, fitness: npt.ArrayLike) -> None:
        """The fitness of the rows of the last ask, in their order."""

    @property
    def done(self) -> bool:
        """True once a stopping rule fired (``stop_reason`` says which)."""

    @property
    def best_x(self) -> np.ndarray:
        """The best row told so far (NaN before the first tell)."""

    @property
    def best_f(self) -> float:
        """Its fitness (NaN while nothing succeeded)."""

    @property
    def population(self) -> np.ndarray:
        """The designs the method keeps (a DE's population, CMA-ES's last round), best first."""

    @property
    def fitness(self) -> np.ndarray:
        """Their fitness (NaN = failed)."""

    def state(self, *, history: bool = True, arrays: bool = False) -> dict[str, Any]:
        """Everything needed to continue exactly, as JSON types, with ``"method"`` set; ``arrays=True``
        allows numpy arrays in it (NaN where a value is missing), made JSON types by
        :func:`~finaldrive.engine.optimize.common.plain_json` where it is stored."""

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> Optimiser:
        """The optimiser :meth:`state` was taken from, continuing exactly."""


def register(cls: type[Optimiser]) -> type[Optimiser]:
    """Make a method available by its ``method`` name (to :func:`restore` and the settings)."""
    OPTIMISERS[cls.method] = cls
    return cls


#: The keys of every method's state that hold its :attr:`Optimiser.population` and :attr:`Optimiser.fitness`.
POPULATION_KEYS = ("population", "fitness")


def without_population(state: dict[str, Any]) -> dict[str, Any]:
    """A state without its population and fitness, for a caller that keeps those anyway (the
    scheduler stores them in columns of their own; each was stored twice, 14 % of the writer's
    time on the paper plan went to encoding them as JSON, issue 27)."""
    return {key: value for key, value in state.items() if key not in POPULATION_KEYS}


def with_population(state: dict[str, Any], population: Any, fitness: Any) -> dict[str, Any]:
    """A state taken :func:`without_population` whole again, from its optimiser's ``population`` and
    ``fitness`` as they were then (JSON types, NaN as None); a whole state as it is."""
    if all(key in state for key in POPULATION_KEYS):
        return state
    return {**state, "population": population, "fitness": fitness}


def restore(state: dict[str, Any]) -> Optimiser:
    """Rebuild an optimiser from its state (a state without ``"method"`` is the DE's, as stored
    before methods had names)."""
    method = state.get("method", "de")
    if method not in OPTIMISERS:
        raise ValueError(f"unknown optimiser {method!r} in a stored state")
    return OPTIMISERS[method].from_state(state)
