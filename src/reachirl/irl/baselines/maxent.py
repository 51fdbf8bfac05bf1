"""Classic maximum-entropy IRL (Ziebart et al. 2008) on a sampled trajectory set, in MO-IRL's loop.

The likelihood of a demonstration is ``e^{−ωᵀΦ*} / (e^{−ωᵀΦ*} + Σ_i e^{−ωᵀΦ_i})`` over every trajectory
generated so far (``memory=None``): each sample enters with the weight ``e^{−ωᵀ(Φ_i − Φ*)}`` the likelihood
itself gives it (MO-IRL's γ is exactly that weight, so ``use_gamma`` stays on). Everything else (the
scale-free subproblem, the line search, the merit) is :class:`~reachirl.irl.moirl.MOIRL`'s, so the two differ
only in the sample set: MO-IRL keeps the latest rollout, MaxEnt all of them.
"""

from __future__ import annotations

from typing import ClassVar

from ..moirl import MOIRL

__all__ = ["MaxEntIRL"]


class MaxEntIRL(MOIRL):
    """:class:`MOIRL` that keeps every sampled trajectory in the partition function (``memory=None``, which
    ``experimental`` may override); every other parameter is MOIRL's."""

    _option_defaults: ClassVar[dict] = {"memory": None}
