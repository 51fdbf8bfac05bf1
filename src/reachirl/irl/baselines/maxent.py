"""Classic maximum-entropy IRL (Ziebart et al. 2008) on a sampled trajectory set, in MO-IRL's loop.

The likelihood of a demonstration is ``e^{−ωᵀΦ*} / (e^{−ωᵀΦ*} + Σ_i e^{−ωᵀΦ_i})`` over every trajectory
generated so far (``memory=None``): each sample enters with the weight ``e^{−ωᵀ(Φ_i − Φ*)}`` the likelihood
itself gives it (MO-IRL's γ is exactly that weight, so ``use_gamma`` stays on). Everything else (the
scale-free subproblem, the line search, the merit) is :class:`~reachirl.irl.moirl.MOIRL`'s, so the two differ
only in the sample set: MO-IRL keeps the latest rollout, MaxEnt all of them.
"""

from __future__ import annotations

from ..moirl import MOIRL

__all__ = ["MaxEntIRL"]


class MaxEntIRL(MOIRL):
    """:class:`MOIRL` with ``memory=None`` (every sampled trajectory in the partition function) by default; any
    other MOIRL option passes through."""

    def __init__(self, n_windows: int = 8, *, memory: int | None = None, **kwargs):
        super().__init__(n_windows, memory=memory, **kwargs)
