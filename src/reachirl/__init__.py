"""reachirl: learn which cost a human minimises while reaching, and predict new reaches from it.

Public API (see the README):

* :data:`FEATURES` — the seven cost features, in the seed paper's order.
* :class:`ArmModel` — the planar two-link arm (Dumas 2007 anthropometrics).
* :class:`ReachingTask`, :func:`solve_doc`, :class:`DocSolution` — direct optimal control of a reach.
* :class:`MOIRL` — the MO-IRL estimator with time-varying weights.
"""

import os as _os

# Every matrix here is tiny (2×2 dynamics, 56-weight subproblems): a multi-threaded BLAS only spins, and was
# measured 100× slower in L-BFGS-B on a busy 2-core machine. Must be set before numpy loads; users can override.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

from .arm import ArmModel  # noqa: E402
from .doc import DocSolution, ReachingTask, solve_doc  # noqa: E402
from .features import FEATURES  # noqa: E402

__all__ = ["FEATURES", "MOIRL", "ArmModel", "DocSolution", "ReachingTask", "solve_doc"]
__version__ = "0.1.0"


def __getattr__(name: str):
    # MOIRL pulls in scipy.optimize and the data layer; import it on first use.
    if name == "MOIRL":
        from .irl.moirl import MOIRL

        return MOIRL
    raise AttributeError(f"module 'reachirl' has no attribute {name!r}")


def __dir__() -> list[str]:
    # the lazy MOIRL too: dir(), inspect.getmembers and help() list every public name
    return sorted({*globals(), *__all__})
