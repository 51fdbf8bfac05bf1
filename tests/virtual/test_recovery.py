"""Ground truth, end to end: virtual-subject files → preprocess → MO-IRL → predictions against the truth's.

Measured (seed 3, P2, 10 train / 10 CV trials): 8 windows CV 1.80°, 1.30° from the truth weights' predictions,
merit 0.253 → 0.180; 1 window CV 3.94°; the truth weights themselves 1.67° (trials are jittered around them).
"""

import numpy as np
import pytest

from reachirl import MOIRL, ReachingTask, solve_doc
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
    train, test = trials[:10], trials[10:]
    truth = nominal_weights()
    fits = {n: MOIRL(n_windows=n).fit(train) for n in (1, 8)}
    cv = {n: summarise(evaluate_trials(m.weights_, test))["rmse_deg"]["q"]["mean"] for n, m in fits.items()}
    truth_cv = summarise(evaluate_trials(truth, test))["rmse_deg"]["q"]["mean"]
    agreement = [rmse_deg(fits[8].predict(t).q, solve_doc(ReachingTask.from_trial(t), truth).q)[2] for t in test]

    assert fits[8].merit_ < 0.8 * fits[8].initial_merit_ and fits[8].flag_ is None
    assert np.all(fits[8].weights_ >= 0)
    assert cv[8] < 2.5, cv
    assert cv[8] < truth_cv + 1.0, (cv, truth_cv)
    assert np.mean(agreement) < 2.5, agreement
    assert cv[8] < cv[1], "8 windows must beat 1 when the truth varies in time"
