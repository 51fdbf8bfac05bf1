"""How well the demonstrations determine each MO-IRL weight (identifiability), from the training trials and a
fit's weights, without new DOC solves.

* :func:`difference_conditioning` — the subproblem (seed Eq. 4) sees each weight only through the feature
  differences ``Φ_i − Φ*_d`` (in the scale-free coordinates, ``Φ/σ``). Per window, the singular values of the
  matrix of those differences over the demonstrations (``D × 7``, centred: the spread a step can use) say how
  many weight directions the data can tell apart; the condition number (largest / smallest singular value) is
  how badly the worst direction is determined, and the direction itself names the features that trade off.
* :func:`collinear_pairs` — feature pairs whose running rates ``φ_j(k)`` are nearly collinear along the
  demonstrations (Pearson ``|r|`` over every knot of every training trial, on this arm): such features can
  trade weight without changing the reach (joint acceleration against torque change is the known one).
* :func:`bootstrap_shares` — bootstrap intervals (seeded) of each feature's share of each window's cost,
  ``ω_sj Φ*_sj / Σ_j ω_sj Φ*_sj``, over resampled demonstrations: how much the shares the report shows move
  when the demonstrations are redrawn, at fixed ω. (A refit per resample, which would add the weights' own
  variability, is not done: it costs one MO-IRL fit per resample.)

:func:`identifiability` gathers the three into one JSON-able dict.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..data.trial import Trial
from ..features import FEATURES, feature_rates
from .objective import feature_scale

__all__ = ["bootstrap_shares", "collinear_pairs", "difference_conditioning", "identifiability"]


def _demo_features(trials: Sequence[Trial], n_nodes: int, n_windows: int) -> np.ndarray:
    return np.stack([t.features(n_nodes, n_windows) for t in trials])


def difference_conditioning(phi_demo: np.ndarray, phi_ref: np.ndarray | None = None) -> list[dict]:
    """Per window: singular values, condition number and worst-determined direction of the normalised feature
    differences. ``phi_demo (D, S, 7)``; ``phi_ref (S, 7)`` is the rollout's Φ (default: the demonstrations'
    mean, so the differences are the demonstrations' spread)."""
    phi_demo = np.asarray(phi_demo, dtype=float)
    sigma = feature_scale(phi_demo)
    ref = phi_demo.mean(axis=0) if phi_ref is None else np.asarray(phi_ref, dtype=float)
    out = []
    for s in range(phi_demo.shape[1]):
        diff = (phi_demo[:, s] - ref[s]) / sigma[s]  # (D, 7)
        diff = diff - diff.mean(axis=0) if phi_ref is None else diff
        _, sv, vt = np.linalg.svd(diff, full_matrices=True)
        sv = np.concatenate([sv, np.zeros(len(FEATURES) - sv.size)])  # fewer demonstrations than features
        rank = int(np.sum(sv > 1e-9 * max(sv.max(), 1e-300)))
        cond = float(sv.max() / sv.min()) if rank == len(FEATURES) else float("inf")
        worst = vt[-1]
        top = np.argsort(-np.abs(worst))[:2]
        out.append({
            "window": s + 1,
            "singular_values": sv.tolist(),
            "rank": rank,
            "condition_number": cond,
            "worst_direction": {FEATURES[j]: float(worst[j]) for j in range(len(FEATURES))},
            "worst_pair": [FEATURES[j] for j in top],
        })
    return out


def collinear_pairs(trials: Sequence[Trial], n_nodes: int, threshold: float = 0.9) -> list[dict]:
    """Pairs of features whose running rates correlate with ``|r| ≥ threshold`` over every knot of ``trials``
    (sorted by ``|r|``, largest first)."""
    rates = []
    for t in trials:
        q, qd, tau = t.knots(n_nodes)
        rates.append(feature_rates(t.arm, q, qd, tau, t.duration / n_nodes))
    r = np.corrcoef(np.concatenate(rates).T)
    out = []
    for i in range(len(FEATURES)):
        for j in range(i + 1, len(FEATURES)):
            if np.isfinite(r[i, j]) and abs(r[i, j]) >= threshold:
                out.append({"features": [FEATURES[i], FEATURES[j]], "r": float(r[i, j])})
    return sorted(out, key=lambda d: -abs(d["r"]))


def bootstrap_shares(weights: np.ndarray, phi_demo: np.ndarray, n_boot: int = 200, seed: int = 0) -> dict:
    """``{"shares", "lo", "hi"}`` (each ``(S, 7)``): the cost shares at the demonstrations' mean Φ and their 95 %
    bootstrap interval over ``n_boot`` resamples (with replacement, seeded) of the demonstrations."""
    w = np.asarray(weights, dtype=float)
    phi_demo = np.asarray(phi_demo, dtype=float)

    def shares(phi):
        c = w * phi
        tot = c.sum(axis=1, keepdims=True)
        return np.divide(c, tot, out=np.zeros_like(c), where=tot > 0)

    rng = np.random.default_rng(seed)
    d = phi_demo.shape[0]
    boot = np.stack([shares(phi_demo[rng.integers(0, d, d)].mean(axis=0)) for _ in range(int(n_boot))])
    lo, hi = np.quantile(boot, [0.025, 0.975], axis=0)
    return {"shares": shares(phi_demo.mean(axis=0)).tolist(), "lo": lo.tolist(), "hi": hi.tolist()}


def identifiability(weights: np.ndarray, trials: Sequence[Trial], n_nodes: int, *, n_boot: int = 200,
                    seed: int = 0, threshold: float = 0.9) -> dict:
    """Conditioning, collinear pairs and bootstrap share intervals of one fit (see the module docstring)."""
    w = np.asarray(weights, dtype=float)
    phi = _demo_features(trials, n_nodes, w.shape[0])
    return {
        "n_demonstrations": len(trials),
        "conditioning": difference_conditioning(phi),
        "collinear_pairs": collinear_pairs(trials, n_nodes, threshold),
        "bootstrap_shares": bootstrap_shares(w, phi, n_boot, seed),
    }
