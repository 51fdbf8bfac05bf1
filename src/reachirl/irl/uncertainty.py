"""What the training data determines about a fit's weights, and the costs it cannot tell apart from the fit.

**Determined directions.** The observed training states (every demonstration's rollout, seen as the merit sees
it, each channel scaled as the merit scales it) depend on the log-weights ``η = log ω`` through the DOC's optimum.
Their Jacobian ``J = ∂r/∂η`` (:func:`reachirl.doc.sensitivity.weight_jacobian` through
:func:`reachirl.observation.observed_state_jacobian`; one sparse factorisation per rollout, no solve) gives, by
its singular value decomposition ``J = U S Vᵀ``, the directions of ``η`` that change the reaches (large ``s_k``)
and those that do not. A direction is *determined* when moving the log-weights along it by ``log 2`` (halving or
doubling a weight's combination) raises the merit by more than the data can tell from noise
(:func:`merit_noise`): ``s_k² (log 2)² > δm``. The others are said in words (:func:`describe_direction`): which
features trade against which, in which windows.

**Weights the data cannot tell apart** (:func:`weight_uncertainty`). Candidates ``η = η̂ + V_det S_det⁻¹ z ρ_d +
V_und u ρ_u`` (``z`` standard normal in the determined directions, scaled so that the linearised merit rises by
about ``δm``; ``u`` uniform in ``[−1, 1]`` in the undetermined ones, a prior of at most a factor ``e^{ρ_u}`` on
each combination, ``ρ_u = log 10``) are each solved by the DOC and kept only when a one-sided paired test over
the demonstrations does not find their per-demonstration errors larger than the fit's at the 5 % level
(:func:`indistinguishable`). The scales adapt to the acceptance rate (halved after a rejection streak), so the
samples fill the region the data allows, and every kept sample is a cost whose reaches the training data cannot
tell from the fit's. Each window's cost shares ``ω_sj Φ_sj / Σ_j ω_sj Φ_sj`` are computed on the sample's own
rollout; their intervals are the range over the samples (a region of 95 % confidence, projected), and a share
whose interval is wider than :data:`UNDETERMINED_WIDTH` is reported as undetermined.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..doc.sensitivity import weight_jacobian
from ..features import FEATURES, N_FEATURES
from ..observation import observed_state_jacobian

__all__ = [
    "UNDETERMINED_WIDTH",
    "Determination",
    "describe_direction",
    "determination",
    "indistinguishable",
    "merit_noise",
    "share_intervals",
    "weight_uncertainty",
]

log = logging.getLogger(__name__)

UNDETERMINED_WIDTH = 0.25
"""A share whose interval is wider than this is shown as undetermined, not as a finding."""

PRIOR_LOG_RATIO = float(np.log(10.0))
"""Undetermined directions: the samples move the log-weights along them by at most this (a factor 10)."""

METHOD = ("indistinguishable costs: refits from random costs (other basins) and samples around the fit (Gauss-Newton "
          "model in the determined directions, a uniform prior of a factor 10 in the undetermined ones), each "
          "solved by the DOC and kept when a one-sided paired t-test over the demonstrations (5 %) does not find "
          "its reaches worse than the fit's")


@dataclass(frozen=True)
class Determination:
    """The SVD of the training states' log-weight Jacobian. ``singular_values (P,)`` (descending; the merit rises
    by ``s² t²`` along a unit direction moved by ``t``), ``directions (P, S, 7)`` (unit vectors in log-weights,
    zero on weights the fit does not learn), ``threshold`` (``δm``), ``n_determined``."""

    singular_values: np.ndarray
    directions: np.ndarray
    threshold: float
    n_determined: int

    def to_dict(self, top: int = 3) -> dict:
        return {
            "n_directions": int(self.singular_values.size),
            "n_determined": int(self.n_determined),
            "merit_threshold": float(self.threshold),
            "singular_values": [float(s) for s in self.singular_values],
            "determined": [describe_direction(v) for v in self.directions[: self.n_determined][:top]],
            "undetermined": [describe_direction(v) for v in self.directions[self.n_determined:][-top:]],
        }


def residuals_and_jacobian(est, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each demonstration's scaled residual ``r_d (D, M)`` (so that the merit is ``mean_d ‖r_d‖²``) and its
    Jacobian in the free log-weights ``J_d (D, M, P)``, at the fit's weights and rollouts."""
    n1 = est.n_nodes + 1
    channels = est._channels
    scale = np.sqrt(np.ones(4) if channels is None else np.asarray(channels, dtype=float)) / np.sqrt(n1)
    cols = np.flatnonzero(free.reshape(-1))
    w = est._effective(est._w_fit)
    states, jacs = [], []
    for i, (task, sol) in enumerate(zip(est.tasks_, est.train_solutions_, strict=True)):
        dq = weight_jacobian(task, w, sol).reshape(n1, 2, -1)[:, :, cols]
        states.append(est._state(i, task, sol))
        jacs.append((observed_state_jacobian(sol, task, est._thresholds[i], dq) * scale[None, :, None])
                    .reshape(-1, cols.size))
    x_demos = est._x_demos
    r = np.stack([((states[g] - xd) * scale).reshape(-1) for g, xd in zip(est.task_of_demo_, x_demos, strict=True)])
    J = np.stack([jacs[g] for g in est.task_of_demo_])
    return r, J


def merit_noise(errors: np.ndarray) -> float:
    """``δm``: the rise of the merit the demonstrations can tell from noise, ``t₀.₉₅ · sd(e_d) / √D`` of the
    per-demonstration errors ``e_d`` (at least 1e-12)."""
    e = np.asarray(errors, dtype=float)
    if e.size < 2:
        return float(max(abs(e.mean()), 1e-12))
    return float(max(stats.t.ppf(0.95, e.size - 1) * e.std(ddof=1) / np.sqrt(e.size), 1e-12))


def indistinguishable(errors: np.ndarray, errors_fit: np.ndarray, level: float = 0.05) -> bool:
    """Whether a one-sided paired t-test over the demonstrations does not find the per-demonstration errors
    ``errors (D,)`` larger than the fit's ``errors_fit (D,)`` at ``level``."""
    d = np.asarray(errors, dtype=float) - np.asarray(errors_fit, dtype=float)
    if not np.all(np.isfinite(d)):
        return False
    if d.size < 2 or d.std(ddof=1) == 0:
        return bool(d.mean() <= 0)
    t = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
    return bool(t <= stats.t.ppf(1 - level, d.size - 1))


def determination(r: np.ndarray, J: np.ndarray, free: np.ndarray) -> Determination:
    """The determined and undetermined directions from the residuals ``r (D, M)`` and Jacobians ``J (D, M, P)``."""
    D = r.shape[0]
    A = J.reshape(-1, J.shape[-1]) / np.sqrt(D)
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    threshold = merit_noise(np.sum(r**2, axis=1))
    n_det = int(np.sum(s**2 * np.log(2.0) ** 2 > threshold))
    dirs = np.zeros((vt.shape[0], *free.shape))
    for k, v in enumerate(vt):
        full = np.zeros(free.size)
        full[np.flatnonzero(free.reshape(-1))] = v
        dirs[k] = full.reshape(free.shape)
    return Determination(s, dirs, threshold, n_det)


def describe_direction(v: np.ndarray, top: int = 4) -> str:
    """A direction in log-weights ``(S, 7)`` in words: its largest entries, grouped by feature and sign, e.g.
    "joint_acceleration (windows 1, 8) against joint_torque (windows 3-5)"."""
    v = np.asarray(v, dtype=float)
    mass = v**2
    order = np.argsort(mass.ravel())[::-1]
    keep = [i for i in order[: 3 * top] if mass.ravel()[i] >= 0.1 * mass.ravel()[order[0]]]
    pos, neg = {}, {}
    for i in keep:
        s, j = divmod(int(i), N_FEATURES)
        (pos if v.ravel()[i] > 0 else neg).setdefault(FEATURES[j], []).append(s + 1)

    def words(d):
        parts = sorted(d.items(), key=lambda kv: -len(kv[1]))[:top]
        return ", ".join(f"{f} (window{'s' if len(ws) > 1 else ''} {_ranges(sorted(ws))})" for f, ws in parts)

    if pos and neg:
        return f"{words(pos)} against {words(neg)}"
    return f"{words(pos or neg)} together"


def _ranges(ws: list[int]) -> str:
    out, start = [], ws[0]
    for a, b in zip(ws, [*ws[1:], None], strict=True):
        if b != a + 1:
            out.append(str(start) if start == a else f"{start}-{a}")
            start = b
    return ", ".join(out)


def share_intervals(shares: np.ndarray) -> dict:
    """Per window and feature, the range of the samples' cost shares ``shares (K, S, 7)`` and whether it is
    determined (narrower than :data:`UNDETERMINED_WIDTH`): ``{"low", "high", "determined"}``, each ``S × 7``."""
    lo, hi = shares.min(axis=0), shares.max(axis=0)
    return {"low": lo.tolist(), "high": hi.tolist(), "determined": ((hi - lo) <= UNDETERMINED_WIDTH).tolist()}


def _shares(w: np.ndarray, phi: np.ndarray) -> np.ndarray:
    c = w * phi
    tot = c.sum(axis=-1, keepdims=True)
    return np.divide(c, tot, out=np.zeros_like(c), where=tot > 0)


def weight_uncertainty(est, trials, n_samples: int, random_state: int = 0, restarts: int = 4,
                       restart_iter: int = 10, max_solves_per_sample: int = 4) -> dict:
    """Weight samples the training data cannot tell apart from ``est``'s fit (module docstring).

    Two kinds of sample, each kept only when :func:`indistinguishable` from the fit on real DOC solves:

    * ``restarts`` refits (at most ``restart_iter`` iterations each) from random costs, every window's cost
      shares drawn uniformly on the simplex: other basins of the merit that explain the reaches as well;
    * samples around the fit from the Gauss-Newton model (determined directions) and a uniform prior
      (undetermined ones), their scales halved after three rejections in a row.

    Returns the ``uncertainty`` record of MODEL.json: ``method``, ``weight_samples`` (``K × S × 7``, in the units
    of ``weights``; the fit itself first), ``share_samples``, ``share_intervals``, ``determination``
    (:meth:`Determination.to_dict`), ``modes`` (restarts kept / tried), ``candidates``, ``doc_solves`` and
    ``doc_failures``; ``complete`` is False when fewer than ``n_samples`` were accepted within
    ``max_solves_per_sample × n_samples`` local candidates."""
    rng = np.random.default_rng(np.random.SeedSequence([int(random_state), 0x5EED]))
    free = est._movable(est._w_fit.shape)
    w_hat = est._w_fit
    r, J = residuals_and_jacobian(est, free)
    det = determination(r, J, free)
    errors_fit = np.sum(r**2, axis=1)
    starts = np.array([0])
    sols = est.train_solutions_
    fit_phi = np.mean(est._features(est.tasks_, sols, starts), axis=0)
    samples = [est._effective(w_hat)]
    share_samples = [_shares(samples[0], fit_phi)]
    solves = failures = 0

    def keep(w: np.ndarray, cand) -> bool:
        """Whether the rollouts ``cand`` under ``w`` are indistinguishable from the fit's; keeps the sample."""
        nonlocal failures
        if any(not c.converged for c in cand):
            failures += 1
            return False
        states = [est._state(i, t, c) for i, (t, c) in enumerate(zip(est.tasks_, cand, strict=True))]
        if not indistinguishable(_errors(est, states), errors_fit):
            return False
        we = est._effective(w)
        samples.append(we)
        share_samples.append(_shares(we, np.mean(est._features(est.tasks_, cand, starts), axis=0)))
        return True

    # other basins: short refits from random costs (shares uniform on each window's simplex)
    totals = (samples[0] * fit_phi).sum(axis=1, keepdims=True)
    kept_modes = 0
    for _ in range(restarts):
        shares = rng.dirichlet(np.ones(N_FEATURES), size=w_hat.shape[0])
        w0 = np.where(free, shares * totals / np.maximum(fit_phi, 1e-300), w_hat)
        refit = type(est)(**{**est.get_params(), "uncertainty": None, "callback": None, "max_iter": restart_iter})
        refit._w_init = np.maximum(w0, 1e-12 * w_hat)
        refit.fit(list(trials))
        solves += refit.n_doc_solves_
        cand, runs, _ = est._rollouts(est.tasks_, refit._w_fit, None, est._guesses)  # on the fit's own tasks
        solves += runs
        kept_modes += keep(refit._w_fit, cand)

    # around the fit: Gauss-Newton in the determined directions, a uniform prior in the others
    s = det.singular_values
    vt = det.directions.reshape(det.directions.shape[0], -1)[:, free.reshape(-1)]
    k = det.n_determined
    cols = np.flatnonzero(free.reshape(-1))
    rho_d, rho_u = 1.0, PRIOR_LOG_RATIO
    candidates = streak = 0
    budget = max_solves_per_sample * n_samples
    while len(samples) < n_samples and candidates < budget:
        candidates += 1
        eta = np.zeros(cols.size)
        if k:  # determined: the linearised merit rises by about δm · |z|² / k
            z = rng.standard_normal(k)
            eta += vt[:k].T @ (z * np.sqrt(det.threshold / k) / np.maximum(s[:k], 1e-300)) * rho_d
        if k < cols.size:  # undetermined: uniform, at most rho_u along each direction
            eta += vt[k:].T @ rng.uniform(-1.0, 1.0, cols.size - k) * rho_u
        w = w_hat.copy().reshape(-1)
        w[cols] *= np.exp(eta)
        w = w.reshape(w_hat.shape)
        cand, runs, _ = est._rollouts(est.tasks_, w, sols, est._guesses)
        solves += runs
        if keep(w, cand):
            streak = 0
        else:
            streak += 1
            if streak >= 3:  # the region is smaller than the proposal: shrink it
                rho_d, rho_u, streak = rho_d * 0.5, rho_u * 0.5, 0
    shares = np.stack(share_samples)
    if len(samples) < n_samples:
        log.warning("uncertainty: %d of %d samples accepted within %d candidates", len(samples), n_samples,
                    candidates)
    return {
        "method": METHOD,
        "n_samples": len(samples),
        "complete": len(samples) >= n_samples,
        "weight_samples": np.stack(samples).tolist(),
        "share_samples": shares.tolist(),
        "share_intervals": share_intervals(shares),
        "determination": det.to_dict(),
        "modes": {"kept": kept_modes, "tried": restarts},
        "local_scale_final": rho_u,
        "candidates": candidates,
        "doc_solves": solves,
        "doc_failures": failures,
    }


def _errors(est, states: list[np.ndarray]) -> np.ndarray:
    """Each demonstration's contribution to the merit, ``(D,)``: ``‖x_d − x*_d‖²`` weighted as the merit weighs it."""
    n1 = est.n_nodes + 1
    c = np.ones(4) if est._channels is None else np.asarray(est._channels, dtype=float)
    x = np.stack([states[g] for g in est.task_of_demo_])
    return np.sum((x - est._x_demos) ** 2 * c, axis=(1, 2)) / n1
