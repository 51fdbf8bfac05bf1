"""The report states uncertainty: a difference between section counts is called lower or higher only when a
paired test over the same trials says so, and the seed's numbers are labelled as other data."""

import numpy as np
import pytest

from reachirl.experiments.report import paired_comparison


def _results(rmse_by_sections: dict[int, list[float]]) -> dict:
    out = {}
    for n, values in rmse_by_sections.items():
        trials = [{"id": f"S2/P2/right/T{i}", "rmse_deg": {"q": v}} for i, v in enumerate(values)]
        out[f"moirl-P2-s{n}"] = {"unit": {"method": "moirl", "posture": "P2", "sections": n},
                                 "sets": {"iscv": {"trials": trials}}}
    return out


def test_a_consistent_paired_improvement_is_significant():
    rng = np.random.default_rng(0)
    base = rng.uniform(5, 10, 20)
    c = paired_comparison(_results({1: list(base), 8: list(base - 0.5 - 0.05 * rng.random(20))}), "moirl", "iscv",
                          1, 8, ["P2"])
    assert c["n"] == 20 and c["mean_diff_deg"] == pytest.approx(-0.525, abs=0.03)
    assert c["wilcoxon_p"] < 1e-3 and c["ci95_deg"][1] < 0


def test_a_small_difference_with_sd_3_is_not():
    """The UE-ADL case of the issue: 7.49° against 7.79° with SDs of about 3° is no evidence either way."""
    rng = np.random.default_rng(1)
    a = rng.normal(7.79, 3.0, 10)
    b = a - 0.3 + rng.normal(0, 3.0, 10)
    c = paired_comparison(_results({1: list(a), 8: list(b)}), "moirl", "iscv", 1, 8, ["P2"])
    assert c["wilcoxon_p"] > 0.05 and c["ci95_deg"][0] < 0 < c["ci95_deg"][1]


def test_pairs_only_the_same_trials():
    c = paired_comparison(_results({1: [1.0, 2.0, 3.0], 8: [1.0, 2.0]}), "moirl", "iscv", 1, 8, ["P2"])
    assert c["n"] == 2
    assert paired_comparison(_results({1: [1.0], 8: [2.0]}), "moirl", "iscv", 1, 8, ["P2"]) is None
