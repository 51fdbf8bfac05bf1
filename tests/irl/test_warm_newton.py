"""MO-IRL's ``warm_newton`` (on by default): the line search's warm solves by exact Newton on the knots, with
fatrop where Newton cannot vouch for its answer; off, every warm solve is fatrop's."""

import pytest

from reachirl import MOIRL
from reachirl.data.trial import load_trials, select_trials
from reachirl.irl.options import departures, resolve_options


@pytest.fixture(scope="module")
def p2(recorded):
    return select_trials(load_trials(recorded / "trials.npz"), subjects=["S01"], postures=["P2"])


def test_a_fit_solves_its_line_search_by_newton_unless_told_otherwise(p2):
    fast = MOIRL(2, n_nodes=40, max_iter=4).fit(p2)
    base = MOIRL(2, n_nodes=40, max_iter=4, experimental={"warm_newton": False}).fit(p2)
    assert fast.n_iter_ >= 1 and base.n_iter_ >= 1
    # the accepted tries' rollouts (warm solves of the training tasks) came from Newton, and only there
    assert all(s.status.startswith("newton") for s in fast.train_solutions_)
    assert not any(s.status.startswith("newton") for s in base.train_solutions_)
    # the same optimum at the solvers' tolerance: the fits part only where a line search compares merits at it
    assert fast.merit_ == pytest.approx(base.merit_, rel=0.05)


def test_fatrop_warm_solves_are_a_stated_departure_and_the_option_is_validated(p2):
    options = resolve_options(experimental={"warm_newton": False})
    assert "experimental warm_newton = False" in departures(options, "per_task", 1e-4)
    assert not any("warm_newton" in d for d in departures(resolve_options(), "per_task", 1e-4))
    with pytest.raises(ValueError, match="warm_newton must be True or False, got 'yes'"):
        MOIRL(2, n_nodes=40, experimental={"warm_newton": "yes"}).fit(p2)
