"""Ground truth, end to end: virtual-subject files → preprocess → MO-IRL → predictions against the truth's."""

import numpy as np
import pytest

from reachirl import MOIRL
from reachirl.cli import main
from reachirl.data.trial import load_trials
from reachirl.doc.evaluation import evaluate_trials, rmse_deg, summarise
from reachirl.virtual import SynthConfig, generate, nominal_weights

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    d = tmp_path_factory.mktemp("recovery")
    generate(d, SynthConfig(n_subjects=1, n_trials=20, postures=("P2",), seed=3, workers=2))
    assert (
        main(
            [
                "preprocess",
                "--manifest",
                str(d / "manifest.csv"),
                "--subject-info",
                str(d / "subjects.csv"),
                "--markers",
                "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP",
                "--out",
                str(d / "t.npz"),
            ]
        )
        == 0
    )
    return load_trials(d / "t.npz")


def test_moirl_recovers_the_truths_trajectories(trials):
    """The default fit (observed rollouts) predicts held-out reaches as well as the true weights, as recorded."""
    train, test = trials[:10], trials[10:]
    truth = nominal_weights()
    fits = {n: MOIRL(n_windows=n).fit(train) for n in (1, 8)}

    def predicted(model, weights):
        return evaluate_trials(weights, test, observe=True, path=None if model is None else model.rollout_path())

    cv = {n: summarise(predicted(m, m.weights_))["rmse_deg"]["q"]["mean"] for n, m in fits.items()}
    truth_pred = predicted(None, truth)
    truth_cv = summarise(truth_pred)["rmse_deg"]["q"]["mean"]
    agreement = [rmse_deg(fits[8].predict(t).q, e.prediction.q)[2] for t, e in zip(test, truth_pred, strict=True)]

    first = fits[8].plain_fit_  # the whole-rollout first stage learned, and the observed stage went on
    assert first["merit"] < 0.8 * first["initial_merit"] and fits[8].flag_ is None
    assert np.all(fits[8].weights_ >= 0)
    assert cv[8] < 2.5, cv
    assert cv[8] < truth_cv + 1.0, (cv, truth_cv)
    assert np.mean(agreement) < 2.5, agreement
    assert cv[8] < cv[1], "8 windows must beat 1 when the truth varies in time"
