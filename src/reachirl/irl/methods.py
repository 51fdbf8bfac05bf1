"""The IRL methods by name, for the command line and the benchmarks: ``make_estimator("moirl", 8)``."""

from __future__ import annotations

from .baselines import KKTIOC, BilevelIOC, MaxEntIRL
from .moirl import MOIRL

__all__ = ["METHODS", "builds_on_moirl", "make_estimator"]

METHODS: dict[str, type] = {"moirl": MOIRL, "maxent": MaxEntIRL, "bilevel": BilevelIOC, "kkt": KKTIOC}


def builds_on_moirl(method: str) -> bool:
    """Whether ``method`` is MO-IRL or an estimator built on it (MaxEnt): it iterates up to ``max_iter`` per stage,
    takes MO-IRL's options (rollout, seed form, experimental) and draws weight samples; bilevel and KKT do not."""
    cls = METHODS.get(method)
    return cls is not None and issubclass(cls, MOIRL)


def make_estimator(method: str, n_windows: int, **kwargs):
    """A new, unfitted estimator of ``method`` (one of :data:`METHODS`) with ``n_windows`` windows; ``kwargs``
    are its hyperparameters (e.g. ``n_nodes``, ``max_iter`` for MO-IRL, ``max_evals`` for bilevel)."""
    try:
        cls = METHODS[method]
    except KeyError:
        raise ValueError(f"unknown IRL method {method!r}; choose one of {tuple(METHODS)}") from None
    return cls(n_windows, **kwargs)
