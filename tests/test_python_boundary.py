"""What a researcher meets using reachirl from Python (a notebook) rather than the command line: the frozen data's
arrays, the estimators' checks and reprs, the protocol's configuration."""

from __future__ import annotations

import numpy as np
import pytest

from reachirl.data.trial import Trial


def _trial(arm, **kw) -> Trial:
    t = np.linspace(0.0, 0.6, 13)
    q = np.c_[np.linspace(-1.4, -0.6, 13), np.linspace(1.5, 0.5, 13)]
    zero = np.zeros_like(q)
    return Trial("S1", "P2", "T1", kw.pop("t", t), q, zero, zero, zero, 0.5, arm, **kw)


def test_a_trial_keeps_its_own_read_only_time_and_start(arm):
    t, x0 = np.linspace(0.0, 0.6, 13), np.array([-1.4, 1.5, 0.0, 0.0])
    tr = _trial(arm, t=t, x0=x0)
    x0[0], t[-1] = 100.0, 50.0  # the caller's arrays, changed after: not the trial's
    assert tr.x0[0] == -1.4 and tr.duration == pytest.approx(0.6)
    for name in ("t", "x0", "q", "qd", "qdd", "tau"):  # a frozen trial: none of its arrays changes in place
        with pytest.raises(ValueError, match="read-only"):
            getattr(tr, name)[0] = 1.0


def test_a_task_keeps_its_own_read_only_start_and_bounds(arm):
    from reachirl.doc.task import ReachingTask

    q0, lower, row = np.array([-1.0, 1.2]), np.array([-2.6, 0.05]), np.array([[-1.0, 1.2]])
    view = np.array([-1.0, 1.2]).view()
    view.setflags(write=False)  # read-only, but a view of an array its owner may still change
    task = ReachingTask(arm, q0, 0.5, 0.8, n_nodes=20, q_lower=lower)
    from_view = ReachingTask(arm, view, 0.5, 0.8, n_nodes=20)
    from_row = ReachingTask(arm, row, 0.5, 0.8, n_nodes=20)  # (1, 2): reshaped
    q0[0], lower[0], view.base[0], row[0, 0] = 9.0, 1.0, 9.0, 9.0  # the caller's arrays, changed after
    assert task.q0.tolist() == [-1.0, 1.2] and task.q_lower[0] == -2.6
    assert from_view.q0[0] == -1.0 and from_row.q0[0] == -1.0
    for name in ("q0", "q_lower", "q_upper", "qd_max"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(task, name)[0] = 1.0
    again = ReachingTask(arm, task.q0, 0.6, 0.8, n_nodes=20)  # another task's start: its own already, shared
    assert again.q0 is task.q0


@pytest.fixture(scope="module")
def fitted(tiny_trials):
    from reachirl.data.trial import load_trials
    from reachirl.irl.baselines import KKTIOC

    return KKTIOC(2, n_nodes=20).fit(load_trials(tiny_trials)[:3])


@pytest.mark.parametrize("empty", [[], (), iter([])], ids=["list", "tuple", "iterator"])
def test_scoring_no_trials_is_a_value_error_not_minus_infinity(fitted, empty):
    # -inf is the score of a model whose every prediction failed; an empty set is the caller's mistake
    with pytest.raises(ValueError, match="at least one trial"):
        fitted.score(empty)


@pytest.mark.parametrize(
    "kw", [{"sections": 8}, {"postures": "P2"}, {"methods": "kkt"}], ids=["sections", "postures", "methods"]
)
def test_protocol_config_takes_a_single_name_or_number_as_a_sequence_of_one(kw):
    from reachirl.experiments.protocol import ProtocolConfig

    # postures="P2" ran postures "P" and "2"; methods="kkt" said unknown method 'k'; sections=8 a TypeError
    (name,) = kw
    assert ProtocolConfig(**kw) == ProtocolConfig(**{name: [kw[name]]})
    assert getattr(ProtocolConfig(**kw), name) == (kw[name],)


def test_an_estimators_repr_names_its_class_and_the_parameters_changed():
    from reachirl import MOIRL
    from reachirl.irl.baselines import KKTIOC, BilevelIOC, MaxEntIRL

    assert repr(MOIRL()) == "MOIRL()"
    assert repr(MOIRL(4, max_iter=5, rollout="per_demo")) == "MOIRL(n_windows=4, rollout='per_demo', max_iter=5)"
    assert repr(MaxEntIRL(8, tol=0.001)) == "MaxEntIRL(tol=0.001)"
    assert repr(BilevelIOC(2, method="nelder-mead")) == "BilevelIOC(n_windows=2, method='nelder-mead')"
    assert repr(KKTIOC().set_params(pooling="per_demo")) == "KKTIOC(pooling='per_demo')"
    mask = np.ones(7, dtype=bool)
    assert repr(MOIRL(feature_mask=mask)) == f"MOIRL(feature_mask={mask!r})"


def test_a_learned_models_repr_summarises_its_provenance(fitted, tiny_trials):
    from reachirl.data.trial import load_trials
    from reachirl.irl.model import LearnedModel

    model = LearnedModel.from_estimator(fitted, load_trials(tiny_trials)[:3])
    rollout = {"history": [{"merit": 1.0, "weights": model.weights.tolist()}] * 300}
    big = LearnedModel(model.weights, model.n_nodes, model.method, {**model.info, **rollout})
    text = repr(big)  # a notebook prints a loaded model whole: it was over 100,000 characters for one fit
    assert text.startswith("LearnedModel(weights=array(") and "method='kkt'" in text and len(text) < 2000
    assert f"info=<{len(big.info)} keys>, uncertainty=None)" in text


def test_a_learned_model_keeps_its_own_read_only_weights():
    from reachirl.irl.model import LearnedModel

    w = np.full((2, 7), 0.1)
    model = LearnedModel(w, n_nodes=20)
    w[0, 0] = -5.0  # the caller's array (an estimator's weights_) changed after: not the model's
    assert model.weights[0, 0] == 0.1
    with pytest.raises(ValueError, match="read-only"):
        model.weights[0, 0] = -5.0  # past the check that weights are >= 0


def _uncertainty(n_windows: int) -> dict:
    shares = [[1 / 7] * 7] * n_windows
    return {
        "n_samples": 1,
        "weight_samples": [[[0.1] * 7] * n_windows],
        "share_intervals": {"low": shares, "high": shares, "determined": [[True] * 7] * n_windows},
    }


def test_a_learned_models_info_and_uncertainty_are_read_only(tmp_path):
    # a frozen model's info and uncertainty were plain dicts: changed in place (or through the caller's dict), the
    # model changed past the checks of its construction
    import copy
    import pickle
    from dataclasses import replace

    from reachirl.irl.model import LearnedModel, load_model, save_model

    info = {"backend": "casadi", "history": [{"iteration": 0, "merit": 1.0}], "warnings": ["w"]}
    unc = _uncertainty(2)
    model = LearnedModel(np.full((2, 7), 0.1), n_nodes=20, info=info, uncertainty=unc)
    info["backend"], unc["n_samples"] = "crocoddyl", 5  # the caller's dicts, changed after: not the model's
    assert model.backend == "casadi" and model.uncertainty["n_samples"] == 1
    with pytest.raises(TypeError, match="does not support item assignment"):
        model.info["backend"] = "crocoddyl"  # past the check of info.backend
    with pytest.raises(TypeError, match="does not support item assignment"):
        model.info["history"][0]["merit"] = float("nan")
    with pytest.raises(AttributeError, match="'tuple' object has no attribute 'append'"):
        model.info["warnings"].append("x")
    with pytest.raises(TypeError, match="does not support item assignment"):
        model.uncertainty["share_intervals"]["low"] = None
    with pytest.raises(TypeError, match="does not support item assignment"):
        model.uncertainty["weight_samples"][0][0] = [-1.0] * 7

    # the file, equality, copies and the repr work as before
    assert load_model(save_model(tmp_path / "m.json", model)) == model
    plain = {"backend": "casadi", "history": [{"iteration": 0, "merit": 1.0}], "warnings": ["w"]}
    assert model.to_dict()["info"] == plain
    assert type(model.to_dict()["uncertainty"]["share_intervals"]) is dict
    assert pickle.loads(pickle.dumps(model)) == model and copy.deepcopy(model) == model
    changed = replace(model, info={**model.info, "backend": "crocoddyl"})
    assert changed.backend == "crocoddyl" and changed != model and model.backend == "casadi"
    assert repr(model).endswith("info=<3 keys>, uncertainty=<1 weight samples>)")


@pytest.mark.parametrize("n_nodes", [3, 100_000])
def test_an_estimators_n_nodes_out_of_range_is_named_as_its_own(tiny_trials, n_nodes):
    from reachirl import MOIRL
    from reachirl.data.trial import load_trials
    from reachirl.irl.baselines import KKTIOC

    trials = load_trials(tiny_trials)[:1]
    for est in (MOIRL(1, n_nodes=n_nodes), KKTIOC(1, n_nodes=n_nodes)):
        name = type(est).__name__
        with pytest.raises(ValueError, match=rf"^{name}: n_nodes must be an integer in \[4, 1000\], got {n_nodes}$"):
            est.fit(trials)


def test_protocol_config_takes_numpy_numbers_for_tol_and_uncertainty():
    from reachirl.experiments.protocol import ProtocolConfig

    # "uncertainty must be 0 (none) or a number of samples from 20 to 1000, got np.int64(20)": it is one
    config = ProtocolConfig(tol=np.float64(1e-3), uncertainty=np.int64(20), seed=np.int64(1))
    assert (config.tol, config.uncertainty) == (1e-3, 20)
    assert type(config.tol) is float and type(config.uncertainty) is int
    assert ProtocolConfig(uncertainty=20) == ProtocolConfig(uncertainty=np.int64(20))
    with pytest.raises(ValueError, match="uncertainty must be 0"):
        ProtocolConfig(uncertainty=np.int64(5))


def test_a_task_starting_outside_the_joint_limits_names_each_joints_range(arm):
    from reachirl import ReachingTask

    # the limits read "[[-150. -5.], [120. 160.]] deg": the lower bounds, then the upper ones
    with pytest.raises(
        ValueError,
        match=r"^q0 = \(-90\.0°, -20\.0°\) lies outside the joint limits q1 in \[-150\.0°, 120\.0°\], "
        r"q2 in \[-5\.0°, 160\.0°\]$",
    ):
        ReachingTask(arm, np.deg2rad([-90, -20]), 0.5, 0.7)
    with pytest.raises(ValueError, match=r"q0 = \(-5156\.6°, 5156\.6°\) .*; radians are expected \(degrees\?\)$"):
        ReachingTask(arm, [-90, 90], 0.5, 0.7)  # np.deg2rad forgotten


@pytest.mark.parametrize("t", [0.0, np.zeros((3, 1)), np.zeros(1)], ids=["scalar", "2-d", "one knot"])
def test_a_doc_solution_with_a_bad_time_vector_is_a_value_error_naming_it(t):
    from reachirl import DocSolution

    z = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"^DocSolution\.t must have shape \(N\+1,\) with N >= 1, got "):
        DocSolution(t, z, z, z[:2], 0.0, True, 0, 0.0)


@pytest.mark.parametrize("given", ["one trial", "a file name", "a list of names"])
def test_saving_a_model_names_trials_that_are_not_a_sequence_of_trial(fitted, tiny_trials, given):
    from reachirl.data.trial import load_trials
    from reachirl.irl.model import LearnedModel

    trials = load_trials(tiny_trials)[:3]
    arg = {"one trial": trials[0], "a file name": str(tiny_trials), "a list of names": ["T0", "T1"]}[given]
    with pytest.raises(TypeError, match=r"^trials must be the sequence of Trial the estimator was fitted on, got a "):
        LearnedModel.from_estimator(fitted, arg)


@pytest.mark.parametrize("workers", ["2", None, 0, 2.5, True])
def test_reproduce_refuses_a_number_of_workers_that_is_not_one_before_any_work(tmp_path, workers):
    from reachirl.experiments.datasets import toy
    from reachirl.experiments.protocol import ProtocolConfig
    from reachirl.experiments.runner import reproduce

    dataset = toy(postures=("P2",), n_trials=2, n_nodes=20)
    config = ProtocolConfig(sections=(1,), n_train=1, n_nodes=20, max_iter=1, uncertainty=0)
    out = tmp_path / "run"
    # "2" and None failed mid-run ('<=' not supported between 'str' and 'int'), after the folder was made
    with pytest.raises(ValueError, match=r"^workers must be a number of worker processes, at least 1 .*, got "):
        reproduce(dataset, config, out, workers=workers)
    assert not out.exists()


@pytest.mark.parametrize("shape", [(2, 5), (5, 3), (3,), ()], ids=["joints first", "three columns", "three", "scalar"])
def test_the_arms_kinematics_and_dynamics_refuse_arrays_without_a_pair_per_row(arm, shape):
    # a joints-first (2, n) array, or three columns, was read by its first two columns: a wrong answer, silently
    bad, ok = np.zeros(shape), np.zeros((5, 2))
    calls = {
        "fk": lambda: arm.fk(bad),
        "elbow": lambda: arm.elbow(bad),
        "jacobian": lambda: arm.jacobian(bad),
        "ik": lambda: arm.ik(bad),
        "mass_matrix": lambda: arm.mass_matrix(bad),
        "gravity_torque": lambda: arm.gravity_torque(bad),
        "fingertip_velocity": lambda: arm.fingertip_velocity(ok, bad),
        "fingertip_speed": lambda: arm.fingertip_speed(ok, bad),
        "coriolis": lambda: arm.coriolis(ok, bad),
        "inverse_dynamics": lambda: arm.inverse_dynamics(ok, ok, bad),
        "forward_dynamics": lambda: arm.forward_dynamics(ok, ok, bad),
    }
    for name, call in calls.items():
        with pytest.raises(ValueError, match=rf"^ArmModel\.{name}: \w+ must have shape \(\.\.\., 2\), .*got \("):
            call()
    assert arm.fk(ok).shape == (5, 2) and arm.fk(ok[0]).shape == (2,)  # a pair, or pairs: as before


def test_estimators_give_scikit_learn_the_tags_its_model_selection_reads(monkeypatch):
    import sys
    import types
    from dataclasses import dataclass, field

    from reachirl import MOIRL
    from reachirl.irl.baselines import KKTIOC, BilevelIOC, MaxEntIRL

    @dataclass
    class TargetTags:
        required: bool

    @dataclass
    class InputTags:
        two_d_array: bool = True

    @dataclass
    class Tags:
        estimator_type: str | None
        target_tags: TargetTags
        no_validation: bool = False
        input_tags: InputTags = field(default_factory=InputTags)

    # scikit-learn's own classes where it is installed (it is no dependency): the fields reachirl sets
    fake = types.ModuleType("sklearn.utils")
    fake.Tags, fake.TargetTags, fake.InputTags = Tags, TargetTags, InputTags
    monkeypatch.setitem(sys.modules, "sklearn", types.ModuleType("sklearn"))
    monkeypatch.setitem(sys.modules, "sklearn.utils", fake)
    for est in (MOIRL(), MaxEntIRL(), BilevelIOC(), KKTIOC()):
        tags = est.__sklearn_tags__()
        assert tags.estimator_type is None and tags.target_tags.required is False  # fit takes no y
        assert tags.input_tags.two_d_array is False and tags.no_validation is True  # Trial objects, checked by fit


def test_cross_val_score_runs_on_a_list_of_trials(tiny_trials):
    pytest.importorskip("sklearn", minversion="1.6")
    from sklearn.model_selection import KFold, cross_val_score

    from reachirl.data.trial import load_trials
    from reachirl.irl.baselines import KKTIOC

    # scikit-learn >= 1.6 refused it: "'KKTIOC' object has no attribute '__sklearn_tags__'"
    scores = cross_val_score(KKTIOC(1, n_nodes=20), load_trials(tiny_trials)[:4], cv=KFold(2))
    assert scores.shape == (2,) and np.all(scores < 0)


def test_a_saved_model_records_the_trials_its_estimator_was_fitted_on(fitted, tiny_trials):
    from reachirl.data.trial import load_trials
    from reachirl.irl.model import LearnedModel

    trials = load_trials(tiny_trials)
    own = tuple(t.id for t in trials[:3])
    # left out, the record is the fit's own (it was empty: n_trials 0, no ids)
    assert LearnedModel.from_estimator(fitted).info["trial_ids"] == own
    assert LearnedModel.from_estimator(fitted, load_trials(tiny_trials)[:3]).info["trial_ids"] == own  # read again
    # other trials were written as the fit's: another subject's ids, postures and fingerprint in MODEL.json
    for other in (trials[3:6], trials[:2], trials[2::-1]):
        with pytest.raises(ValueError, match=r"^trials must be the 3 the estimator was fitted on \(the first '"):
            LearnedModel.from_estimator(fitted, other)


def test_scoring_one_trial_names_score_not_evaluate(fitted, tiny_trials):
    from reachirl.data.trial import load_trials

    with pytest.raises(TypeError, match=r"^score takes a sequence of Trial, got a Trial$"):
        fitted.score(load_trials(tiny_trials)[0])


@pytest.mark.parametrize(("name", "value"), [("w0", "0.05"), ("beta", "1e-10"), ("max_tries", "3"), ("shrink", "0.5")])
def test_an_option_given_as_text_is_named_not_compared(name, value):
    from reachirl.irl.options import Options

    # "0.05" passed the finiteness check and failed the next comparison: "'>' not supported between 'str' and 'int'"
    with pytest.raises(ValueError, match=rf"^{name} must be an? (number|integer), not text \(got '{value}'\)$"):
        Options(**{name: value})


def test_the_arms_dynamics_refuse_arrays_of_different_lengths_and_text(arm):
    five, four = np.zeros((5, 2)), np.zeros((4, 2))
    for name, call in {
        "inverse_dynamics": lambda: arm.inverse_dynamics(five, four, five),
        "forward_dynamics": lambda: arm.forward_dynamics(five, five, np.zeros((1, 2))),
        "coriolis": lambda: arm.coriolis(four, five),
    }.items():
        with pytest.raises(ValueError, match=rf"^ArmModel\.{name}: the arrays must have one shape, got q \("):
            call()
    with pytest.raises(ValueError, match=r"^ArmModel\.fk: q must be numbers of shape \(\.\.\., 2\), got 'ab'$"):
        arm.fk("ab")
    tau = arm.inverse_dynamics(five + 0.3, five + 1.0, five - 2.0)  # one shape: as before
    assert np.allclose(arm.forward_dynamics(five + 0.3, five + 1.0, tau), -2.0)


_PER_TIME = r"q must have shape \(10, 2\), one \(q1, q2\) per time, "


@pytest.mark.parametrize(
    ("t", "q", "message"),
    [
        (np.linspace(0, 1, 10), np.zeros((12, 2)), _PER_TIME + r"got \(12, 2\)"),
        (np.linspace(0, 1, 10), np.zeros((2, 10)), _PER_TIME + r"got \(2, 10\)"),
        (np.zeros((3, 1)), np.zeros((3, 2)), r"t must be a 1-D array of at least 3 times, got shape \(3, 1\)"),
        ("abc", np.zeros((3, 2)), r"t and q must be numbers \(could not convert string to float: 'abc'\)"),
    ],
    ids=["more knots", "joints first", "column of times", "text"],
)
def test_a_trial_from_knots_names_the_array_of_the_wrong_shape(arm, t, q, message):
    from reachirl.data.trial import trial_from_knots

    # numpy's own words before: "operands could not be broadcast together with shapes (11,2) (9,1)"
    with pytest.raises(ValueError, match=rf"^trial_from_knots: {message}$"):
        trial_from_knots(arm, t, q, 0.3)


def test_anthropometric_ranges_include_the_ends_their_messages_quote():
    from reachirl import ArmModel

    # "hand_m 0.02 is not a segment length in metres (0.02-1.0)": the message's range contradicted the check
    assert ArmModel.from_anthropometrics(1.76, 70.0, "M", hand_m=0.02, upper_arm_m=1.0).l1 == 1.0
    assert ArmModel.from_anthropometrics(2.6, 300.0, "M").length > 0
    with pytest.raises(ValueError, match=r"^hand_m 0\.019 is not a segment length in metres \(0\.02-1\.0\)"):
        ArmModel.from_anthropometrics(1.76, 70.0, "M", hand_m=0.019)


def test_a_trial_whose_target_is_not_where_it_ends_is_refused_by_fit_and_by_a_trials_file(tiny_trials, tmp_path):
    import dataclasses

    from reachirl import MOIRL
    from reachirl.data.trial import load_trials, save_trials
    from reachirl.errors import InputError

    trials = load_trials(tiny_trials)[:2]
    end = float(trials[1].arm.fk(trials[1].q[-1])[0])
    # a target of another reach (or in other units) was fitted without a word: the DOC's bar, not the reach's end
    moved = [trials[0], dataclasses.replace(trials[1], target_x=end - 0.25)]
    where = rf"^trial 1 \({trials[1].id}\): field 'target_x' = {end - 0.25:.4g} m is 0\.250 m from where the reach ends"
    with pytest.raises(InputError, match=where):
        MOIRL(n_windows=1, n_nodes=20, max_iter=1).fit(moved)
    with pytest.raises(InputError, match=r"moved\.npz: trial 1 .*field 'target_x' = .* from where the reach ends"):
        save_trials(tmp_path / "moved.npz", moved)  # nor written to a trials file, which load_trials checks alike
    assert not (tmp_path / "moved.npz").exists()
    # short of the bar, as recordings end, or on an arm whose segments are the subject-info file's: taken
    near = [trials[0], dataclasses.replace(trials[1], target_x=end - 0.15)]
    assert load_trials(save_trials(tmp_path / "near.npz", near))[1].target_x == end - 0.15


def test_a_model_whose_sample_count_contradicts_its_samples_is_refused(tmp_path):
    import json

    from reachirl.errors import InputError
    from reachirl.irl.model import LearnedModel, load_model, save_model

    path = save_model(tmp_path / "m.json", LearnedModel(np.full((2, 7), 0.1), n_nodes=20, uncertainty=_uncertainty(2)))
    d = json.loads(path.read_text())
    d["uncertainty"]["n_samples"] = 7
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"field 'uncertainty\.weight_samples': 1 samples, but .*n_samples' says 7"):
        load_model(path)
    d["uncertainty"]["n_samples"] = "1"
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"field 'uncertainty\.n_samples': expected a count >= 0, found '1'"):
        load_model(path)
