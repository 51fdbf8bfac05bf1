"""The benchmark scripts in ``benchmarks/`` run with the options they offer."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


def test_learned_weights_gives_each_method_only_the_budget_it_takes(tmp_path, monkeypatch):
    # --max-iter reached KKTIOC, which takes no max_iter: `--methods kkt` stopped with a TypeError
    import learned_weights

    from reachirl.irl import methods

    built = {}

    def fake_fit(self, trials):  # the fit itself is not what is checked here
        built[type(self).__name__] = self.get_params()
        self.weights_ = np.full((self.n_windows, 7), 0.05)
        return self

    for cls in methods.METHODS.values():
        monkeypatch.setattr(cls, "fit", fake_fit)
    out = tmp_path / "fits.json"
    argv = ["--methods", "kkt", "moirl", "maxent", "bilevel", "--sections", "1", "--sources", "builtin"]
    learned_weights.main([*argv, "--postures", "P1", "--max-iter", "3", "--max-evals", "7", "--out", str(out)])
    fits = json.loads(out.read_text())["fits"]
    assert [f["method"] for f in fits] == ["kkt", "moirl", "maxent", "bilevel"]
    assert "max_iter" not in built["KKTIOC"] and "max_evals" not in built["KKTIOC"]
    assert built["MOIRL"]["max_iter"] == 3 and built["MaxEntIRL"]["max_iter"] == 3
    assert built["BilevelIOC"]["max_evals"] == 7


@pytest.mark.parametrize("method", ["moirl", "maxent", "bilevel", "kkt"])
def test_learned_weights_budget_builds_every_method(method):
    import learned_weights

    from reachirl.irl.methods import make_estimator

    est = make_estimator(method, 2, **learned_weights.fit_budget(method, 4, 9))
    assert est.n_nodes == 100
