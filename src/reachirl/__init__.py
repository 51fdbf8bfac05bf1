"""reachirl: learn which cost a human minimises while reaching, and predict new reaches from it.

Public API (see the README):

* :data:`FEATURES` — the seven cost features, in the seed paper's order.
* :class:`ArmModel` — the planar two-link arm (Dumas 2007 anthropometrics).
* :class:`ReachingTask`, :func:`solve_doc`, :class:`DocSolution` — direct optimal control of a reach.
* :class:`MOIRL` — the MO-IRL estimator with time-varying weights.
"""

from .arm import ArmModel
from .doc import DocSolution, ReachingTask, solve_doc
from .features import FEATURES

__all__ = ["FEATURES", "ArmModel", "DocSolution", "MOIRL", "ReachingTask", "solve_doc"]
__version__ = "0.1.0"


def __getattr__(name: str):
    # MOIRL pulls in scipy.optimize and the data layer; import it on first use.
    if name == "MOIRL":
        from .irl.moirl import MOIRL

        return MOIRL
    raise AttributeError(f"module 'reachirl' has no attribute {name!r}")
