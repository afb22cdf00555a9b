"""Optimisers: pure numerics over numpy arrays, nothing from the rest of ``engine``.

:class:`DifferentialEvolution` is the paper's DE (section 4, Fig. 7, Table 10) as an
ask/tell state machine; see docs/optimisation.md.
"""

from finaldrive.engine.optimize.de import DifferentialEvolution

__all__ = ["DifferentialEvolution"]
