"""Baseline IRL/IOC methods behind MOIRL's estimator interface (``fit(trials) -> self``, ``weights_``,
``history_``, ``n_doc_solves_``, ``n_iter_``, ``fit_time_``, ``predict``):

* :class:`MaxEntIRL`: classic maximum-entropy IRL (MO-IRL's loop, all trajectories kept, no γ scaling);
* :class:`BilevelIOC`: derivative-free outer search with a DOC per evaluation (Mombaur; Berret 2011);
* :class:`KKTIOC`: residual IOC from the DOC's stationarity conditions, one NNLS (Englert; Colombel 2022).
"""

from .bilevel import BilevelIOC
from .kkt import KKTIOC
from .maxent import MaxEntIRL

__all__ = ["KKTIOC", "BilevelIOC", "MaxEntIRL"]
