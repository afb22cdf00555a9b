"""Optimisers: pure numerics over numpy arrays, nothing from the rest of ``engine``.

Every method follows :class:`Optimiser` (ask/tell of whole batches, a JSON state, per-round
records) and is registered by name: :class:`DifferentialEvolution` is the paper's DE (section 4,
Fig. 7, Table 10), :class:`CMAES` is IPOP-CMA-ES; see docs/optimisation.md.
"""

from finaldrive.engine.optimize.cma_es import CMAES
from finaldrive.engine.optimize.common import plain_json
from finaldrive.engine.optimize.de import DifferentialEvolution
from finaldrive.engine.optimize.protocol import (
    OPTIMISERS,
    Optimiser,
    register,
    restore,
    with_population,
    without_population,
)

register(DifferentialEvolution)
register(CMAES)

__all__ = ["CMAES", "OPTIMISERS", "DifferentialEvolution", "Optimiser", "plain_json", "register", "restore",
           "with_population", "without_population"]
