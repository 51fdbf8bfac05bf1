"""What the training data determines about a fit's weights, and how uncertain they are.

**Determined directions.** The observed training states (every demonstration's rollout, seen as the merit sees
it, each channel scaled as the merit scales it) depend on the log-weights ``η = log ω`` through the DOC's optimum.
Their Jacobian ``J = ∂r/∂η`` (:func:`reachirl.doc.sensitivity.weight_jacobian` through
:func:`reachirl.doc.observation.observed_state_jacobian`; one sparse factorisation per rollout, no solve) gives, by
its singular value decomposition ``J = U S Vᵀ``, the directions of ``η`` that change the reaches (large ``s_k``)
and those that do not. A direction is *determined* when moving the log-weights along it by ``log 2`` (halving or
doubling a weight's combination) raises the merit by more than the data can tell from noise
(:func:`merit_noise`): ``s_k² (log 2)² > δm``. The others are said in words (:func:`describe_direction`): which
features trade against which, in which windows.

**Weight samples** (:func:`weight_uncertainty`): the Laplace posterior of the free log-weights
(:func:`laplace_posterior`), with the merit's Gauss-Newton model ``2 gᵀ(η − η̂) + (η − η̂)ᵀ A (η − η̂)`` as the
likelihood's exponent (centred on the model's own minimum, not on a fit that stopped short of it) at the scale
``τ = δm / 4`` (a move to a direction's 95 % edge raises the merit by ``δm``) and a prior ``N(log ω₀, (log 250)²)``
per log-weight, centred on ``ω₀`` (equal shares of each window's demonstrated cost, on the demonstrations' Φ*) and
wide enough to exclude no share the report can print
(:data:`PRIOR_LOG_SD`). In the determined directions the data
narrows the samples; in the others the prior speaks, and the intervals say so. Each window's cost shares
``ω_sj Φ_sj / Σ_j ω_sj Φ_sj`` are computed on the fit's own reach; their 95 % intervals are the 2.5 and 97.5
percentiles over the draws, and a share whose interval is wider than :data:`UNDETERMINED_WIDTH`, or does not
contain the fit's own share, is reported as undetermined. A few samples are solved by the DOC and tested against
the fit (:func:`indistinguishable`: a merit rise within the noise ``δm``, or not significant in a
one-sided paired t-test over the demonstrations; ``checked``, with each sample's merit rise in units of ``δm``): the
model is linear, the DOC is not, and the samples far from the fit usually fail the test (docs/method.md: a local
model cannot see the other basins where costs as good as the fit's lie; only the prior's width covers them). On
virtual subjects :func:`versus_fit` applies the same test to the true weights: whether the data can tell the truth's
cost from the fit's.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy import linalg
from scipy.special import stdtrit  # Student's t quantile (scipy.stats's t.ppf; scipy.stats takes 0.3 s to import)

from ..doc.observation import observed_state_jacobian
from ..doc.sensitivity import weight_jacobian
from ..features import FEATURES, N_FEATURES, cost_shares

__all__ = [
    "UNDETERMINED_WIDTH",
    "Determination",
    "claim_verdict",
    "describe_direction",
    "determination",
    "fit_errors",
    "indistinguishable",
    "laplace_posterior",
    "mean_width",
    "merit_noise",
    "one_demo_tasks",
    "prior_gives_verdict",
    "residuals_and_jacobian",
    "rise_over_noise",
    "rollout_errors",
    "share_intervals",
    "versus_fit",
    "weight_uncertainty",
]

log = logging.getLogger(__name__)

_ACC = FEATURES.index("joint_acceleration")

DEFAULT_SAMPLES = 40
"""Weight samples drawn when asked for without a number: ``reachirl fit --uncertainty`` and
``MOIRL(uncertainty=True)``."""

UNDETERMINED_WIDTH = 0.25
"""A share whose interval is wider than this is shown as undetermined, not as a finding."""

PRIOR_LOG_SD = float(np.log(250.0))
"""The prior's standard deviation of each log-weight around ``ω₀``: a factor 250, the smallest round factor under
which every share of a 7-feature window has a prior 95 % interval from 0 to 0.995, the report's precision. A
feature that alone makes a window's cost, or plays no part in it, is a share the prior must not rule out: the
paper's own windows are dominated by one feature."""

METHOD = (
    "laplace-gauss-newton: the posterior of the log-weights under the merit's Gauss-Newton model at the fit, "
    "gradient included (likelihood scale: the merit rise the demonstrations can tell from noise) and a prior "
    "centred on w0 (equal shares of the demonstrated cost) with a factor-250 standard deviation (no share the report "
    "prints ruled out)"
)


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
            "undetermined": [describe_direction(v) for v in self.directions[self.n_determined :][-top:]],
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
        jacs.append(
            (observed_state_jacobian(sol, task, est._thresholds[i], dq) * scale[None, :, None]).reshape(-1, cols.size)
        )
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
    return float(max(stdtrit(e.size - 1, 0.95) * e.std(ddof=1) / np.sqrt(e.size), 1e-12))


def indistinguishable(errors: np.ndarray, errors_fit: np.ndarray, level: float = 0.05) -> bool:
    """Whether the demonstrations cannot tell the per-demonstration errors ``errors (D,)`` from the fit's
    ``errors_fit (D,)``: their mean rise is at most the merit noise ``δm`` (:func:`merit_noise`, the rise that
    defines a determined direction), or a one-sided paired t-test over the demonstrations does not find it
    significant at ``level``: told apart only by a rise both beyond the noise and consistent over the
    demonstrations."""
    d = np.asarray(errors, dtype=float) - np.asarray(errors_fit, dtype=float)
    if not np.all(np.isfinite(d)):
        return False
    if d.mean() <= merit_noise(errors_fit):
        return True
    if d.size < 2 or d.std(ddof=1) == 0:
        return bool(d.mean() <= 0)
    t = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
    return bool(t <= stdtrit(d.size - 1, 1 - level))


def rise_over_noise(errors: np.ndarray, errors_fit: np.ndarray) -> float:
    """How much worse than the fit ``errors (D,)`` explain the demonstrations: their mean rise over ``errors_fit
    (D,)``, in units of the merit noise ``δm`` (:func:`merit_noise` of the fit's errors; the determined directions'
    and the posterior's unit). Below 1, a rise the demonstrations cannot tell from noise."""
    e, e_fit = np.asarray(errors, dtype=float), np.asarray(errors_fit, dtype=float)
    return float((e.mean() - e_fit.mean()) / merit_noise(e_fit))


def fit_errors(est) -> np.ndarray:
    """Each demonstration's error ``(D,)`` under the fit's own rollouts, as the merit weighs it."""
    states = [est._state(i, t, s) for i, (t, s) in enumerate(zip(est.tasks_, est.train_solutions_, strict=True))]
    return _errors(est, states)


def versus_fit(est, w: np.ndarray) -> dict:
    """How the training demonstrations judge the weights ``w (S, 7)`` (the DOC's units) against ``est``'s fit:
    its rollouts re-solved under ``w`` (warm from the fit's), then ``verdict``: ``"worse"`` when the samples'
    test (:func:`indistinguishable`) tells ``w``'s errors from the fit's, ``"better"`` when the same test tells the
    fit's from ``w``'s, ``"as good"`` otherwise (the data cannot tell the two costs apart), with
    ``rise_over_noise`` (:func:`rise_over_noise`; negative: ``w`` explains them better) and ``converged`` (a DOC
    failure leaves the other two None). On virtual subjects the true weights' record says whether the data can
    tell the truth's cost from the learned one, and if the truth is better, that the fit stopped short of a cost
    the data prefers."""
    errors, _, _ = rollout_errors(est, np.asarray(w, dtype=float))
    if errors is None:
        return {"converged": False, "verdict": None, "rise_over_noise": None}
    e_fit = fit_errors(est)
    worse, better = not indistinguishable(errors, e_fit), not indistinguishable(e_fit, errors)
    return {
        "converged": True,
        "verdict": "worse" if worse else "better" if better else "as good",
        "rise_over_noise": rise_over_noise(errors, e_fit),
    }


def determination(r: np.ndarray, J: np.ndarray, free: np.ndarray) -> Determination:
    """The determined and undetermined directions from the residuals ``r (D, M)`` and Jacobians ``J (D, M, P)``."""
    D = r.shape[0]
    A = J.reshape(-1, J.shape[-1]) / np.sqrt(D)
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    if vt.shape[0] < A.shape[1]:  # fewer residuals than log-weights: the rest of the space moves nothing
        vt = np.vstack([vt, linalg.null_space(vt).T])
        s = np.concatenate([s, np.zeros(A.shape[1] - s.size)])
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
    "joint_acceleration (windows 1, 8) against joint_torque (windows 3-5)", "energy (windows 2-3) together" when
    every entry moves the same way, "energy (window 1) alone" for a single one."""
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
    return f"{words(pos or neg)} {'alone' if len(keep) == 1 else 'together'}"


def _ranges(ws: list[int]) -> str:
    out, start = [], ws[0]
    for a, b in zip(ws, [*ws[1:], None], strict=True):
        if b != a + 1:
            out.append(str(start) if start == a else f"{start}-{a}")
            start = b
    return ", ".join(out)


def share_intervals(shares: np.ndarray, point: np.ndarray | None = None, free: np.ndarray | None = None) -> dict:
    """Per window and feature, the 95 % interval (2.5 and 97.5 percentiles) of the cost shares ``shares (K, S, 7)``
    and whether it is determined: narrower than :data:`UNDETERMINED_WIDTH` and, given the fit's own shares
    ``point (S, 7)``, containing that share (within 0.005, the printed precision; a fit outside its own narrow
    interval is not a share the data pins down): ``{"low", "high", "determined"}``, each ``S × 7``.

    ``free (S, 7)``: the weights the fit learned (:meth:`MOIRL._movable`). A share whose weight was held fixed (a
    frozen window, a feature removed from the cost), or the share of a window with fewer than two learned weights,
    is the same in every draw: its interval is zero wide because the fit held it, not because the data pins it
    down, and it is never determined."""
    lo, hi = np.percentile(shares, 2.5, axis=0), np.percentile(shares, 97.5, axis=0)
    determined = (hi - lo) <= UNDETERMINED_WIDTH
    if point is not None:
        determined &= (point >= lo - 0.005) & (point <= hi + 0.005)
    out = {"low": lo.tolist(), "high": hi.tolist()}
    if free is not None:
        free = np.asarray(free, dtype=bool)
        learned = free & (free.sum(axis=1, keepdims=True) >= 2)
        determined &= learned
        out["learned"] = learned.tolist()
    out["determined"] = determined.tolist()
    return out


def mean_width(intervals: dict) -> float | None:
    """The mean width of :func:`share_intervals`' 95 % intervals over the shares the fit learned (``learned``;
    every share in a record without it): a share the fit held fixed is zero wide by construction, and averaging it
    in would make the cost look better determined than it is. None when the fit learned no share."""
    width = np.subtract(intervals["high"], intervals["low"])
    learned = intervals.get("learned")
    if learned is not None:
        width = width[np.asarray(learned, dtype=bool)]
    return float(width.mean()) if width.size else None


def laplace_posterior(
    r: np.ndarray, J: np.ndarray, eta_hat: np.ndarray, eta_prior: np.ndarray, prior_sd: float = PRIOR_LOG_SD
) -> tuple[np.ndarray, np.ndarray, float]:
    """The Gauss-Newton (Laplace) posterior of the free log-weights: ``(mean (P,), covariance (P, P), τ)``.

    The likelihood is ``exp(−(m(η) − m̂) / (2τ))`` with the merit's Gauss-Newton model at the fit ``η̂``,
    ``m(η) − m̂ ≈ 2 gᵀ(η − η̂) + (η − η̂)ᵀ A (η − η̂)``, ``g = Σ_d J_dᵀ r_d / D``, ``A = Σ_d J_dᵀJ_d / D``, and
    ``τ = δm / 4`` (:func:`merit_noise`), so that a move to the edge of a direction's 95 % interval raises the merit
    by ``δm``, what the demonstrations can tell from noise; the prior is ``N(η_prior, prior_sd² I)``. The gradient
    term centres the likelihood on the model's own minimum, not on the fit: a fit that stopped short of the
    merit's minimum (its line search found no step the DOC confirms) would otherwise leave the truth outside."""
    D = r.shape[0]
    A = np.einsum("dmp,dmq->pq", J, J) / D
    g = np.einsum("dmp,dm->p", J, r) / D
    tau = merit_noise(np.sum(r**2, axis=1)) / 4.0
    precision = A / tau + np.eye(A.shape[0]) / prior_sd**2
    cov = np.linalg.inv(precision)
    cov = 0.5 * (cov + cov.T)
    mean = cov @ ((A @ eta_hat - g) / tau + eta_prior / prior_sd**2)
    return mean, cov, tau


def weight_uncertainty(
    est, trials, n_samples: int, random_state: int = 0, n_check: int = 10, n_interval: int = 4000
) -> dict:
    """Weight samples of the Gauss-Newton (Laplace) posterior of ``est``'s fit (module docstring).

    The prior centres every free log-weight on ``ω₀`` (every feature with the same share of each window's
    demonstrated cost), with a standard deviation of a factor 250 (:data:`PRIOR_LOG_SD`); the data's likelihood is
    the merit's Gauss-Newton model at the fit. ``n_check`` samples are solved by the DOC and tested with
    :func:`indistinguishable` (``checked``: how many were solved, how many of those pass (the model is linear, the
    DOC is not), each solved sample's merit rise over the fit in units of the merit noise (:func:`rise_over_noise`),
    and how many ``failed``: a sample whose DOC did not converge is counted there, not as solved).

    Returns the ``uncertainty`` record of MODEL.json: ``method``, ``weight_samples`` (``n_samples × S × 7``, in the
    units of ``weights``), ``share_intervals`` (2.5 and 97.5 percentiles of each window's cost shares over
    ``n_interval`` draws, on the fit's own reach, and whether each is determined; the ``n_samples`` weight
    samples are further draws, too few to give the same percentiles), ``share_samples`` (their shares),
    ``claim`` (:func:`claim_verdict` over the interval draws), ``prior`` (its centre and width, and the
    intervals' ``mean_width`` and the claim's ``fraction`` under the prior alone: what the data adds),
    ``determination`` (:meth:`Determination.to_dict`), ``prior``, ``checked``, ``doc_solves`` and, for several
    tasks, ``pooling``: the same intervals' mean width and determined directions from each task's demonstrations
    alone beside the pooled ones (how much pooling narrows them); ``time_s``, its wall time (part of the fit's)."""
    t_start = time.perf_counter()
    rng = np.random.default_rng(np.random.SeedSequence([int(random_state), 0x5EED]))
    free = est._movable(est._w_fit.shape)
    cols = np.flatnonzero(free.reshape(-1))
    r, J = residuals_and_jacobian(est, free)
    det = determination(r, J, free)
    eta_hat = np.log(est._w_fit).reshape(-1)
    eta_prior = np.log(est._w_start).reshape(-1)
    eta_prior = eta_prior - eta_prior[cols].mean() + eta_hat[cols].mean()  # the same overall scale (no effect)
    mean, cov, tau = laplace_posterior(r, J, eta_hat[cols], eta_prior[cols])
    L = np.linalg.cholesky(cov + 1e-12 * np.eye(cov.shape[0]))

    def draw(n: int) -> np.ndarray:
        eta = np.tile(eta_hat, (n, 1))
        eta[:, cols] = mean + (L @ rng.standard_normal((cols.size, n))).T
        return est._effective(np.exp(eta).reshape(n, *est._w_fit.shape))

    phi = est.reach_features()
    samples = draw(n_samples)
    shares = cost_shares(draw(n_interval), phi)
    point = cost_shares(est.weights_, phi)  # the fit's own shares: the ones reported and drawn
    pooling = None
    task_of = np.array(_task_names(trials))
    if len(set(task_of)) > 1:  # how much pooling the tasks narrows the intervals: each task's data alone
        pooling = {"pooled": _width_record(det, share_intervals(shares, point, free)), "per_task": {}}
        for task_trials in dict.fromkeys(task_of.tolist()):
            rows = task_of == task_trials
            det_g = determination(r[rows], J[rows], free)
            mean_g, cov_g, _ = laplace_posterior(r[rows], J[rows], eta_hat[cols], eta_prior[cols])
            Lg = np.linalg.cholesky(cov_g + 1e-12 * np.eye(cov_g.shape[0]))
            eta = np.tile(eta_hat, (n_interval, 1))
            eta[:, cols] = mean_g + (Lg @ rng.standard_normal((cols.size, n_interval))).T
            w_g = est._effective(np.exp(eta).reshape(n_interval, *est._w_fit.shape))
            pooling["per_task"][task_trials] = _width_record(det_g, share_intervals(cost_shares(w_g, phi), point, free))
    errors_fit = np.sum(r**2, axis=1)
    passed = solves = failed = 0
    rises = []
    for w in samples[:n_check]:
        errors, _, runs = rollout_errors(est, w)
        solves += runs
        if errors is None:  # a DOC failure: counted apart, neither solved nor told apart from the fit
            failed += 1
        else:
            passed += indistinguishable(errors, errors_fit)
            rises.append(rise_over_noise(errors, errors_fit))
    # the same quantities under the prior alone: what the data adds (where it determines little, next to nothing)
    prior_rng = np.random.default_rng(np.random.SeedSequence([int(random_state), 0x5EED, 1]))
    eta = np.tile(eta_hat, (n_interval, 1))
    eta[:, cols] = eta_prior[cols] + PRIOR_LOG_SD * prior_rng.standard_normal((n_interval, cols.size))
    prior_shares = cost_shares(est._effective(np.exp(eta).reshape(n_interval, *est._w_fit.shape)), phi)
    prior_intervals = share_intervals(prior_shares, free=free)
    prior = {
        "center": "w0: every feature with the same share of each window's demonstrated cost",
        "log_sd": PRIOR_LOG_SD,
        "mean_width": mean_width(prior_intervals),
        "claim_fraction": claim_verdict(prior_shares, free)["fraction"],
    }
    claim = claim_verdict(shares, free)
    claim["prior_verdict"] = prior_gives_verdict(claim, prior)  # the prior alone gives it too: not a finding
    return {
        "method": METHOD,
        "n_samples": int(n_samples),
        "weight_samples": samples.tolist(),
        "share_samples": cost_shares(samples, phi).tolist(),
        "share_intervals": share_intervals(shares, point, free),
        "claim": claim,
        "determination": det.to_dict(),
        "prior": prior,
        "likelihood_tau": float(tau),
        "checked": {
            "solved": min(n_check, n_samples) - failed,
            "failed": int(failed),
            "indistinguishable": int(passed),
            "rise_over_noise": rises,
        },
        "doc_solves": int(solves),
        "pooling": pooling,
        "time_s": time.perf_counter() - t_start,
    }


def claim_verdict(share_samples: np.ndarray, free: np.ndarray | None = None) -> dict:
    """The paper's claim, "joint acceleration's share at onset and end exceeds its share mid-reach", over the
    weight samples' cost shares ``(K, S, 7)`` (S ≥ 3): ``supported`` when it holds in at least 97.5 % of the
    samples, ``contradicted`` when it holds in at most 2.5 %, ``undetermined`` otherwise; with
    the fraction of samples where it holds and their number (``reason``: why the claim does not apply, else
    None). Onset and end are the first and last windows, mid-reach the others' mean.
    :func:`weight_uncertainty` applies it to the posterior's interval draws (thousands), not to the few weight
    samples. ``free (S, 7)``: the weights the fit learned; where joint acceleration's share was held fixed (its
    weight frozen or removed, or its window's only learned weight), the draws say nothing of the claim there, and
    it does not apply."""
    sh = np.asarray(share_samples, dtype=float)
    n = int(sh.shape[0]) if sh.ndim == 3 else 0
    if sh.ndim != 3 or sh.shape[1] < 3:
        return {"verdict": "not applicable", "fraction": None, "n_samples": n, "reason": "needs at least 3 windows"}
    if free is not None:
        free = np.asarray(free, dtype=bool)
        held = np.flatnonzero(~free[:, _ACC] | (free.sum(axis=1) < 2))
        if held.size:
            windows = ", ".join(str(int(k) + 1) for k in held)
            return {
                "verdict": "not applicable",
                "fraction": None,
                "n_samples": n,
                "reason": f"joint acceleration's share is held fixed by the fit in window(s) {windows}, not learned",
            }
    acc = sh[:, :, _ACC]
    holds = np.minimum(acc[:, 0], acc[:, -1]) > acc[:, 1:-1].mean(axis=1)
    frac = float(holds.mean())
    verdict = "supported" if frac >= 0.975 else "contradicted" if frac <= 0.025 else "undetermined"
    return {"verdict": verdict, "fraction": frac, "n_samples": int(sh.shape[0]), "reason": None}


def prior_gives_verdict(claim: dict, prior: dict | None) -> bool:
    """Whether the prior alone, without the data, gives the claim's verdict too (``supported`` or
    ``contradicted``; its ``claim_fraction`` past the same 97.5 % or 2.5 %): then the verdict is the prior's, not
    a finding of the data. With many windows the prior alone makes joint acceleration's share at both onset and end
    rarely exceed its mean over the others, and the claim then reads *contradicted* with nothing determined."""
    p0 = (prior or {}).get("claim_fraction")
    if p0 is None or claim.get("fraction") is None:
        return False
    return claim.get("verdict") == ("supported" if p0 >= 0.975 else "contradicted" if p0 <= 0.025 else None)


def _width_record(det: Determination, intervals: dict) -> dict:
    return {
        "n_determined": int(det.n_determined),
        "mean_width": mean_width(intervals),
        "undetermined_fraction": float(1.0 - np.mean(intervals["determined"])),
    }


def _task_names(trials) -> list[str]:
    """Each demonstration's task as ``subject/posture``, whatever the rollouts (one per task, per demonstration
    or one for all): the tasks ``pooling`` compares are the data's, not the fit's rollouts."""
    return [f"{t.subject}/{t.posture}" for t in trials]


def one_demo_tasks(trials) -> list[str]:
    """The tasks of ``pooling.per_task`` (:func:`_task_names`, in the trials' order) with a single demonstration:
    their intervals alone rest on :func:`merit_noise`'s stand-in (the merit itself), not on a measured spread.
    Empty with a single task (no ``pooling`` then)."""
    names = _task_names(trials)
    counts = Counter(names)
    return [] if len(counts) < 2 else [n for n in counts if counts[n] == 1]


def rollout_errors(est, w: np.ndarray) -> tuple[np.ndarray | None, list, int]:
    """``est``'s training rollouts re-solved under the weights ``w (S, 7)`` (warm from the fit's; far from them:
    the interior point on the knots where Newton gives way): each demonstration's error ``(D,)`` as the merit
    weighs it (None when a solve failed), the solutions, and the solver runs spent."""
    cand, runs, _ = est._rollouts(est.tasks_, w, est.train_solutions_, est._guesses, far=True)
    if not all(c.converged for c in cand):
        return None, cand, runs
    states = [est._state(i, t, c) for i, (t, c) in enumerate(zip(est.tasks_, cand, strict=True))]
    return _errors(est, states), cand, runs


def _errors(est, states: list[np.ndarray]) -> np.ndarray:
    """Each demonstration's contribution to the merit, ``(D,)``: ``‖x_d − x*_d‖²`` weighted as the merit weighs it."""
    n1 = est.n_nodes + 1
    c = np.ones(4) if est._channels is None else np.asarray(est._channels, dtype=float)
    x = np.stack([states[g] for g in est.task_of_demo_])
    return np.sum((x - est._x_demos) ** 2 * c, axis=(1, 2)) / n1
