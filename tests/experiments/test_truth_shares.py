"""The learned-vs-true comparison weighs both sets of weights on the true weights' own noise-free reach."""

import numpy as np

from reachirl.data.trial import trial_from_knots
from reachirl.experiments.analysis import reference_features, true_weights
from reachirl.experiments.datasets import toy


def _one_trial():
    ds = toy(n_subjects=1, postures=("P2",), n_trials=1, n_nodes=40, seed=3)
    trial = ds.trials[0]
    return trial, true_weights(ds.truth, [trial.trial_id])


def test_a_doc_reach_is_its_own_reference():
    # the toy trial is the DOC solution of its own task under its own weights: the reference DOC (mean task of
    # that one trial) must be the same reach, so the same features
    trial, w = _one_trial()
    ref = reference_features([trial], w, 40)
    own = trial.features(40, w.shape[0])
    assert ref.shape == own.shape == w.shape
    np.testing.assert_allclose(ref, own, rtol=2e-3, atol=1e-9 * own.max())


def test_reference_ignores_the_recordings_noise():
    # 0.1 deg of position noise (what a 10 Hz filter may leave) multiplies the recorded torque change many times;
    # the reference reach, rebuilt from the recorded start, target and duration, stays within a few percent
    trial, w = _one_trial()
    rng = np.random.default_rng(0)
    q = trial.q + np.deg2rad(rng.normal(0.0, 0.1, trial.q.shape))
    q[0] = trial.q[0]
    noisy = trial_from_knots(trial.arm, trial.t, q, trial.target_x, trial.subject, trial.posture, trial.trial_id)
    clean = trial.features(40, w.shape[0])
    tc = 4  # torque change
    assert noisy.features(40, w.shape[0])[:, tc].sum() > 10 * clean[:, tc].sum()
    ref = reference_features([noisy], w, 40)
    np.testing.assert_allclose(ref.sum(axis=0), clean.sum(axis=0), rtol=0.05)


def test_reference_of_cut_trials_is_seen_as_they_were_recorded():
    # a "recorded" reach: the rest-to-rest DOC under w, cut where the fingertip speed crosses 5 % of its peak.
    # Seen the same way, the reference (rebuilt from the cut start, target and duration) has the recording's
    # windows; the plain DOC over the cut duration does not
    from dataclasses import replace

    from reachirl.doc import ReachingTask, solve_doc
    from reachirl.doc.observation import observe, rest_to_rest

    trial, w = _one_trial()
    task = rest_to_rest(ReachingTask.from_trial(trial, 40))
    sol = solve_doc(task, w)
    assert sol.converged
    cut = replace(
        observe(sol, task, 0.05),
        subject="S01",
        posture="P2",
        trial_id="T01",
        onset_threshold=0.05,
        target_x=task.target_x,
    )
    own = cut.features(40, w.shape[0])
    seen = reference_features([cut], w, 40, observe=True)
    whole = reference_features([cut], w, 40, observe=False)
    err_seen = np.abs(seen - own).sum(axis=0) / own.sum(axis=0)
    assert np.all(err_seen < 0.25), err_seen
    assert np.abs(seen - own).sum() < 0.5 * np.abs(whole - own).sum()
