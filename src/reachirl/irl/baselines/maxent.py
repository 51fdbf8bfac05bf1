"""Classic maximum-entropy IRL (Ziebart et al. 2008) in MO-IRL's loop: every generated trajectory stays in the
partition function (``memory=None``) and none is scaled by its current optimality (``use_gamma=False``, i.e.
``γ_i = 1``). Everything else (subproblem, line search, merit) is :class:`~reachirl.irl.moirl.MOIRL`'s, so the
two differ only in those two choices.
"""

from __future__ import annotations

from ..moirl import MOIRL

__all__ = ["MaxEntIRL"]


class MaxEntIRL(MOIRL):
    """:class:`MOIRL` with ``memory=None`` and ``use_gamma=False`` by default (any other MOIRL option passes
    through)."""

    def __init__(self, n_windows: int = 8, *, memory: int | None = None, use_gamma: bool = False, **kwargs):
        super().__init__(n_windows, memory=memory, use_gamma=use_gamma, **kwargs)
