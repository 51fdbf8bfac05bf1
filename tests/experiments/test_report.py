"""The report says what was done: the method and each departure from the paper, from the recorded options; a
difference between section counts judged on postures (one fit each), never on trials of one fit; figures and
captions that name what they show."""

import numpy as np
import pytest

from reachirl.experiments import figures as fg
from reachirl.experiments.analysis import paired_comparison, signed_rank_p
from reachirl.experiments.method import convergence_text, method_lines
from reachirl.experiments.protocol import ProtocolConfig
from reachirl.experiments.report import prediction_note, protocol_line, weights_caption
from reachirl.features import FEATURES


def _results(rmse: dict[int, dict[str, list[float]]]) -> dict:
    """``rmse[sections][posture]``: the per-trial RMSE of q of one fit."""
    out = {}
    for n, by_posture in rmse.items():
        for p, values in by_posture.items():
            trials = [{"id": f"S2/{p}/right/T{i}", "rmse_deg": {"q": v}} for i, v in enumerate(values)]
            out[f"moirl-{p}-s{n}"] = {
                "unit": {"method": "moirl", "posture": p, "sections": n},
                "sets": {"iscv": {"trials": trials}},
            }
    return out


def test_fifty_trials_of_two_fits_are_two_samples_not_fifty():
    rng = np.random.default_rng(0)
    base = {p: rng.uniform(5, 10, 25) for p in ("P1", "P2")}
    c = paired_comparison(
        _results({1: base, 8: {p: v - 0.5 for p, v in base.items()}}), "moirl", "iscv", 1, 8, ["P1", "P2"]
    )
    assert c["n"] == 2 and c["n_lower"] == 2 and c["mean_diff_deg"] == pytest.approx(-0.5)
    assert c["per_posture"] == pytest.approx({"P1": -0.5, "P2": -0.5})
    assert c["wilcoxon_p"] == pytest.approx(0.5) and c["min_p"] == pytest.approx(0.5)  # no evidence either way


def test_the_signed_rank_p_value_is_scipys_exact_one():
    # counted in reachirl (scipy.stats costs a run half a second to import and tear down): the same number as
    # scipy's exact test, ties (mean ranks, the rank sum rounded away from the centre) and zeros (dropped) included
    import warnings

    from scipy.stats import wilcoxon

    rng = np.random.default_rng(7)
    cases = [rng.normal(size=n) for n in range(1, 16)]
    cases += [rng.integers(-3, 4, size=n).astype(float) for n in range(2, 16) for _ in range(20)]
    cases += [np.round(rng.normal(size=n), 1) for n in range(2, 12) for _ in range(10)]
    compared = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy warns that ties make its exact test conservative
        for d in cases:
            if np.any(d != 0):
                assert signed_rank_p(d) == float(wilcoxon(d, method="exact").pvalue), d
                compared += 1
    assert compared > 350
    assert signed_rank_p([0.0, 0.0]) == 1.0  # nothing to rank
    assert signed_rank_p(-np.arange(1.0, 7.0)) == 2 / 64  # all six lower: the smallest p six postures can give


def test_six_postures_all_lower_reach_significance_and_mixed_ones_do_not():
    postures = [f"P{i}" for i in range(1, 7)]
    a = {p: [5.0 + i, 6.0 + i] for i, p in enumerate(postures)}
    lower = paired_comparison(
        _results({1: a, 8: {p: [v - 0.3 - 0.1 * i for v in a[p]] for i, p in enumerate(postures)}}),
        "moirl",
        "iscv",
        1,
        8,
        postures,
    )
    assert lower["n"] == 6 and lower["wilcoxon_p"] == pytest.approx(2 / 64)
    mixed = paired_comparison(
        _results({1: a, 8: {p: [v + (-1) ** i * (0.1 + 0.1 * i) for v in a[p]] for i, p in enumerate(postures)}}),
        "moirl",
        "iscv",
        1,
        8,
        postures,
    )
    assert mixed["n_lower"] == 3 and mixed["wilcoxon_p"] > 0.05


def test_postures_pair_on_the_trials_both_fits_predicted():
    c = paired_comparison(
        _results({1: {"P1": [1.0, 2.0, 9.0], "P2": [1.0]}, 8: {"P1": [1.0, 2.0], "P2": [2.0]}}),
        "moirl",
        "iscv",
        1,
        8,
        ["P1", "P2"],
    )
    assert c["per_posture"] == pytest.approx({"P1": 0.0, "P2": 1.0})
    assert paired_comparison(_results({1: {"P1": [1.0]}, 8: {"P1": [2.0]}}), "moirl", "iscv", 1, 8, ["P1"]) is None
    # a prediction whose DOC failed (its RMSE is recorded, converged false) is not compared: on the others only
    results = _results({1: {"P1": [1.0, 2.0], "P2": [1.0]}, 8: {"P1": [1.0, 2.0], "P2": [2.0]}})
    results["moirl-P1-s8"]["sets"]["iscv"]["trials"][1].update(rmse_deg={"q": 90.0}, converged=False)
    c = paired_comparison(results, "moirl", "iscv", 1, 8, ["P1", "P2"])
    assert c["per_posture"] == pytest.approx({"P1": 0.0, "P2": 1.0})


def _unit(options, tol=None, method="moirl"):
    return {"method": method, "posture": "P2", "estimator_options": options, "tol": tol}


def test_the_method_lines_name_each_departure_used():
    lines = "\n".join(method_lines([_unit([["experimental", []], ["rollout", "per_task"], ["seed_form", False]])]))
    for departure in (
        "observed rollouts",
        "normalised merit",
        "merit fallback",
        "scale-free steps",
        "acceptance threshold",
    ):
        assert departure in lines
    assert "6 departure(s) from the paper" in lines and "This is the paper's method" not in lines
    assert "one rollout per task" not in lines  # one posture of one subject: one task, the paper's one rollout
    assert "seed defaults otherwise" not in lines


def test_an_option_set_back_to_the_papers_is_no_departure():
    lines = "\n".join(
        method_lines(
            [_unit({"seed_form": False, "rollout": "per_task", "experimental": {"observe": False, "fallback": None}})]
        )
    )
    assert "normalised merit" in lines and "observed rollouts" not in lines and "merit fallback" not in lines


def test_a_seed_form_run_is_said_to_be_the_papers_method():
    lines = method_lines([_unit({"seed_form": True, "rollout": "mean", "experimental": {}}), _unit({}, method="kkt")])
    assert "This is the paper's method" in lines[0] and "β = 1e-10, ω₀ = 0.05" in lines[0]
    assert "departure" not in lines[0]
    assert lines[1] == "- **kkt:** a baseline, with its own options (not MO-IRL's)."


def test_maxents_own_memory_is_its_method_not_a_departure():
    """MaxEnt keeps every sampled rollout (memory = None): that defines it, so its seed form is the paper's
    iteration with that one setting, and its default departs from the paper as MO-IRL's does, no more."""
    seed = method_lines([_unit({"seed_form": True, "rollout": "mean", "experimental": {}}, method="maxent")])[0]
    assert "departure" not in seed and "maxent's own memory = None" in seed and "This is the paper's method" not in seed
    default = "\n".join(method_lines([_unit({"seed_form": False, "rollout": "per_task"}, method="maxent")]))
    assert "experimental memory" not in default and "maxent's own memory = None" in default
    assert "6 departure(s) from the paper" in default


def test_convergence_axes_name_the_merit_and_where_iteration_0_is():
    hist = {("P1", 2): [{"iteration": 0, "merit": 0.5}, {"iteration": 1, "merit": 0.4}]}
    words = convergence_text({"merit": "normalised", "observe": True})
    ax = fg.plot_convergence(hist, [2], merit_label=words["merit_label"], start=words["start"]).axes[0]
    assert "rad" not in ax.get_ylabel() and "unitless" in ax.get_ylabel()
    assert "first stage" in ax.get_xlabel() and "ω₀" not in ax.get_xlabel()
    assert "not the initial weights ω₀" in words["caption"] and "no units" in words["caption"]
    seed = convergence_text({"merit": "state", "observe": False})
    assert "q in rad" in seed["merit_label"] and seed["start"] == "the initial weights ω₀"


def _intervals(shares: np.ndarray, width: np.ndarray) -> dict:
    lo, hi = np.clip(shares - width / 2, 0, 1), np.clip(shares + width / 2, 0, 1)
    return {"low": lo.tolist(), "high": hi.tolist(), "determined": (hi - lo <= 0.25).tolist()}


def test_fig3_caption_quotes_only_determined_shares_with_their_intervals():
    one = np.zeros((1, 7))
    one[0, FEATURES.index("torque_change")] = 0.7
    one[0, FEATURES.index("joint_torque")] = 0.3
    eight = np.full((8, 7), 0.02)
    eight[:, FEATURES.index("joint_torque")] = 0.5
    eight[:, FEATURES.index("joint_velocity")] = 0.4
    wide = np.ones((8, 7))
    narrow_acc = wide.copy()
    narrow_acc[0, FEATURES.index("joint_torque")] = 0.1  # P2's first window: joint torque 0.5 [0.45, 0.55]
    shares = {("P1", 1): one, ("P2", 1): one, ("P1", 8): eight, ("P2", 8): eight}
    intervals = {
        ("P1", 1): _intervals(one, np.ones((1, 7))),
        ("P2", 1): _intervals(one, np.ones((1, 7))),
        ("P1", 8): _intervals(eight, wide),
        ("P2", 8): _intervals(eight, narrow_acc),
    }
    caption = weights_caption(shares, intervals)
    assert "1 section: 0 of 14 shares determined." in caption  # the 0.7 torque change is not quoted
    assert "torque change 0.70" not in caption and "70 %" not in caption
    assert "8 sections: 1 of 112 shares determined, the largest P2 window 1 joint torque 0.50 [0.45, 0.55]" in caption
    assert "on the fit's own reach" in caption and "Hatched: undetermined" in caption
    no_samples = weights_caption(shares, {k: v for k, v in intervals.items() if k[1] == 8}, on_reach=False)
    assert "1 section: no weight samples, no share is a finding" in no_samples
    assert "on the training demonstrations" in no_samples


def test_weights_vs_truth_orders_postures_naturally():
    shares = {p: np.full((2, 7), 1 / 7) for p in ("P2", "P10", "P1", "P3")}
    fig = fg.plot_truth(shares, shares)
    assert [ax.get_title() for ax in fig.axes[:4]] == ["P1", "P2", "P3", "P10"]


def test_the_rmse_note_says_how_each_methods_predictions_were_made():
    observed = {"seed_form": False, "rollout": "per_task", "experimental": {}}
    assert prediction_note([_unit(observed)]).startswith("each prediction is the rest-to-rest DOC")
    assert prediction_note([_unit({"seed_form": True, "rollout": "mean"})]).startswith(
        "each prediction is the DOC from the trial's own initial state"
    )
    mixed = prediction_note([_unit(observed), _unit({}, method="kkt")])
    assert mixed.startswith("the predictions of moirl are the rest-to-rest DOC") and "those of kkt, the DOC" in mixed


def test_the_weights_figure_hatches_exactly_the_undetermined_shares():
    shares = np.full((3, 7), 1 / 7)
    undetermined = np.zeros((3, 7), dtype=bool)
    undetermined[0, 2] = undetermined[2, 6] = undetermined[1, 0] = True
    fig = fg.plot_weights({("P1", 3): shares}, ["P1"], [3], undetermined={("P1", 3): undetermined})
    (patch,) = [p for p in fig.axes[0].patches if p.get_hatch()]
    centres = {tuple(np.round(poly[:4].mean(axis=0), 6)) for poly in patch.get_path().to_polygons()}
    # window w (x = w + 1) and feature j (y = j) of each hatched cell
    assert centres == {(w + 1.0, float(j)) for w, j in zip(*np.nonzero(undetermined), strict=True)}
    none = fg.plot_weights({("P1", 3): shares}, ["P1"], [3], undetermined={("P1", 3): np.zeros((3, 7), bool)})
    assert not [p for p in none.axes[0].patches if p.get_hatch()]


def test_the_hatching_shows_on_every_share_dark_or_light():
    # white hatching at alpha 0.6 on viridis' bright end (a share near 1, the one a reader would quote) changed the
    # cell's luminance by about 0.07: the undetermined share looked unhatched, a finding
    import io

    from PIL import Image

    values = np.linspace(0, 1, 8)
    fig = fg.plot_weights(
        {("P1", 8): np.tile(values[:, None], (1, 7))}, ["P1"], [8], undetermined={("P1", 8): np.ones((8, 7), bool)}
    )
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    img = np.asarray(Image.open(buf).convert("RGB"), dtype=float) / 255
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    to_px = fig.axes[0].transData.transform
    for w in range(8):  # each window's cell of the middle feature, inside its borders
        (x0, y0), (x1, y1) = to_px((w + 0.6, 3.4)), to_px((w + 1.4, 2.6))
        rows = sorted(int(img.shape[0] - y) for y in (y0, y1))
        cell = lum[rows[0] : rows[1], int(x0) : int(x1)]
        assert cell.size > 100
        assert cell.max() - cell.min() > 0.2, (values[w], cell.max() - cell.min())


def _hatched_cells(ax) -> set:
    patches = [p for p in ax.patches if p.get_hatch()]
    return {tuple(np.round(poly[:4].mean(axis=0), 6)) for p in patches for poly in p.get_path().to_polygons()}


def test_a_fit_without_weight_samples_is_hatched_whole_beside_fits_with_them():
    # P2's fit has no samples (its uncertainty failed): under the caveat "hatched: undetermined", an unhatched
    # panel would read as determined shares
    shares = {("P1", 2): np.full((2, 7), 1 / 7), ("P2", 2): np.full((2, 7), 1 / 7)}
    fig = fg.plot_weights(shares, ["P1", "P2"], [2], undetermined={("P1", 2): np.zeros((2, 7), bool)})
    assert not _hatched_cells(fig.axes[0])
    assert _hatched_cells(fig.axes[1]) == {(w + 1.0, float(j)) for w in range(2) for j in range(7)}
    assert any("no weight samples" in t.get_text() for t in fig.axes[1].texts)
    assert not any("no weight samples" in t.get_text() for t in fig.axes[0].texts)
    truth = fg.plot_truth(
        {"P1": shares[("P1", 2)], "P2": shares[("P2", 2)]},
        {"P1": shares[("P1", 2)], "P2": shares[("P2", 2)]},
        undetermined={"P1": np.zeros((2, 7), bool)},
    )
    assert len(_hatched_cells(truth.axes[1])) == 14 and not _hatched_cells(truth.axes[0])


def test_weights_vs_truth_says_its_shares_are_on_the_truths_reach_not_the_fits():
    from reachirl.experiments.report import truth_reach_words

    shares = {"P1": np.full((2, 7), 1 / 7)}
    fig = fg.plot_truth(shares, shares, undetermined={"P1": np.zeros((2, 7), bool)}, on="the true weights' own reach")
    footer = " ".join(t.get_text() for t in fig.texts)
    assert "shares on the fit's own reach" not in footer
    assert "both rows' shares on the true weights' own reach" in footer and "on the fit's own reach" in footer
    metrics = {"P1": {"shares_on": "true_rollout"}, "P3": {"shares_on": "demonstrations"}}
    assert truth_reach_words(metrics).endswith("(P3: the training demonstrations', where that reach did not converge)")
    assert truth_reach_words({"P1": {"shares_on": "true_rollout"}}) == "the true weights' own noise-free reach"
    assert truth_reach_words({"P1": {"shares_on": "demonstrations"}}).startswith("the training demonstrations")


def test_the_learned_dominant_features_at_the_ends_say_how_many_are_determined():
    from reachirl.experiments.report import ends_determined_words

    acc, tq = FEATURES.index("joint_acceleration"), FEATURES.index("joint_torque")
    determined = np.zeros((3, 7), bool)
    determined[0, acc] = True  # P1's first window: its dominant feature's share is determined
    determined[2, acc] = True  # not P1's last window's dominant feature (joint torque)
    results = {
        "moirl-P1-s3": {
            "unit": {"method": "moirl", "posture": "P1", "sections": 3},
            "uncertainty": {"share_intervals": {"determined": determined.tolist()}},
        },
        "moirl-P2-s3": {"unit": {"method": "moirl", "posture": "P2", "sections": 3}, "uncertainty": None},
    }
    metrics = {
        "P1": {"sections": 3, "learned_dominant": [FEATURES[acc], FEATURES[tq], FEATURES[tq]]},
        "P2": {"sections": 3, "learned_dominant": [FEATURES[acc]] * 3},
    }
    words = ends_determined_words(results, "moirl", metrics)
    assert words.startswith("1 of 4 of those shares") and "2 without weight samples" in words
    assert words.endswith("not a finding")
    assert ends_determined_words(results, "moirl", {"P2": metrics["P2"]}) == "no weight samples: not a finding"


def test_the_hardest_postures_are_a_ranking_of_means_with_their_spread():
    from reachirl.experiments.report import hardest_words

    tab = {
        p: {"cv": {8: {"q": {"mean": m, "std": sd, "n": 10}}}}
        for p, m, sd in (("P1", 0.72, 0.27), ("P2", 1.21, 0.35), ("P3", 1.33, 0.31), ("P5", 1.39, 0.85))
    }
    words = hardest_words(tab, ["P1", "P2", "P3", "P5"], 8)
    assert "P5 (1.39 ± 0.85°), P3 (1.33 ± 0.31°), then P2 (1.21 ± 0.35°)" in words
    assert "not tested" in words and "Hardest" not in words
    two = hardest_words(tab, ["P2", "P5"], 8)  # two postures: one above the other, not both "highest"
    assert "Higher mean CV RMSE (8 sections): P5 (1.39 ± 0.85°) than P2 (1.21 ± 0.35°)" in two


def test_the_scale_free_departure_says_where_the_weights_start():
    from reachirl.irl.options import departures, resolve_options

    (text,) = [d for d in departures(resolve_options(False, {"w0": 0.1}), "mean", 1e-4) if "scale-free" in d]
    assert "ω₀ = 0.1 and β in those coordinates" in text and "not at 0.1 each" in text
    assert not [d for d in departures(resolve_options(True), "mean", 0.0) if "scale-free" in d]


def test_the_cost_section_says_how_many_re_solved_samples_are_as_good_as_the_fit():
    from types import SimpleNamespace

    from reachirl.experiments.cost import cost_section

    unc = {
        "determination": {"n_determined": 1, "n_directions": 14, "determined": ["energy (window 1) together"]},
        "share_intervals": {"low": np.zeros((2, 7)).tolist(), "high": np.ones((2, 7)).tolist(), "determined": []},
        "prior": {"mean_width": 0.99, "claim_fraction": None},
        "claim": {"verdict": "not applicable", "fraction": None},
        "checked": {"solved": 10, "indistinguishable": 0},
    }
    unc["share_intervals"]["determined"] = np.zeros((2, 7), bool).tolist()
    run = SimpleNamespace(
        results={"moirl-P1-s2": {"key": "moirl-P1-s2", "unit": {"posture": "P1"}, "uncertainty": unc}}
    )
    lines = cost_section(run)
    (header,) = [line for line in lines if line.startswith("| unit |")]
    (row,) = [line for line in lines if line.startswith("| moirl-P1-s2 |")]
    cells = dict(zip(header.strip("| ").split(" | "), row.strip("| ").split(" | "), strict=True))
    assert cells["samples as good as the fit"] == "0 of 10"
    assert any("not costs shown to explain the reaches equally well" in line for line in lines)
    # a sample whose DOC failed is said apart, not hidden among the solved ones
    unc["checked"] = {"solved": 7, "failed": 3, "indistinguishable": 0}
    (row,) = [line for line in cost_section(run) if line.startswith("| moirl-P1-s2 |")]
    cells = dict(zip(header.strip("| ").split(" | "), row.strip("| ").split(" | "), strict=True))
    assert cells["samples as good as the fit"] == "0 of 7 (3 DOC failed)"
    # how far from "as good" the samples are, in units of the merit noise
    unc["checked"] = {"solved": 3, "failed": 0, "indistinguishable": 1, "rise_over_noise": [52.4, -0.31, 6180.2]}
    (row,) = [line for line in cost_section(run) if line.startswith("| moirl-P1-s2 |")]
    cells = dict(zip(header.strip("| ").split(" | "), row.strip("| ").split(" | "), strict=True))
    assert cells["samples as good as the fit"] == "1 of 3 (rise −0.31×-6180× noise)"


def test_on_virtual_subjects_the_cost_section_says_whether_the_data_tells_the_truth_from_the_fit():
    from types import SimpleNamespace

    from reachirl.experiments.cost import cost_section

    unc = {
        "determination": {"n_determined": 0, "n_directions": 14, "determined": []},
        "share_intervals": {
            "low": np.zeros((2, 7)).tolist(),
            "high": np.ones((2, 7)).tolist(),
            "determined": np.zeros((2, 7), bool).tolist(),
        },
        "prior": {"mean_width": 0.99, "claim_fraction": None},
        "claim": {"verdict": "not applicable", "fraction": None},
        "checked": {"solved": 10, "indistinguishable": 0},
    }
    same = {"converged": True, "verdict": "as good", "rise_over_noise": 0.19}
    apart = {"converged": True, "verdict": "worse", "rise_over_noise": 35.2}
    preferred = {"converged": True, "verdict": "better", "rise_over_noise": -3.04}
    results = {
        f"moirl-{p}-s2": {
            "key": f"moirl-{p}-s2",
            "unit": {"posture": p, "sections": 2},
            "uncertainty": unc,
            "truth_solves": {"versus_fit": v},
        }
        for p, v in (("P1", same), ("P2", apart), ("P3", {"converged": False}), ("P4", None), ("P5", preferred))
    }
    true = {p: np.full((2, 7), 1 / 7) for p in ("P1", "P2", "P3", "P4", "P5")}
    metrics = {
        p: {
            "sections": 2,
            "mean_total_variation": tv,
            "truth_versus_fit": results[f"moirl-{p}-s2"]["truth_solves"]["versus_fit"],
        }
        for p, tv in (("P1", 0.81), ("P2", 0.3), ("P3", 0.5), ("P4", 0.5), ("P5", 0.6))
    }
    # a unit of another section count than the truth's gets no judgement (truth_comparison has none for it)
    results["moirl-P1-s3"] = {**results["moirl-P1-s2"], "key": "moirl-P1-s3", "unit": {"posture": "P1", "sections": 3}}
    lines = cost_section(SimpleNamespace(results=results), true, metrics)
    (header,) = [line for line in lines if line.startswith("| unit |")]
    said = {}
    for p in ("P1", "P2", "P3", "P4", "P5"):
        (row,) = [line for line in lines if line.startswith(f"| moirl-{p}-s2 |")]
        said[p] = dict(zip(header.strip("| ").split(" | "), row.strip("| ").split(" | "), strict=True))
    (row,) = [line for line in lines if line.startswith("| moirl-P1-s3 |")]
    assert row.rstrip().endswith("| — |")
    assert [said[p]["truth against the fit"] for p in ("P1", "P2", "P3", "P4", "P5")] == [
        "as good (0.19× noise)",
        "worse (35× noise)",
        "— (DOC failed)",
        "—",
        "better (−3× noise)",
    ]
    # the sentence counts the fits where the truth was re-solved, and the share distance where it is as good
    (sentence,) = [line for line in lines if line.startswith("The truth's cost explains")]
    assert "on 1 of 3 2-section fits" in sentence and "lie 0.81-0.81 apart" in sentence
    assert "on 1 the data prefers the truth's cost, and the fit stopped short of it" in sentence
    # without the truth: neither the column nor the sentence
    lines = cost_section(SimpleNamespace(results=results))
    assert "truth against the fit" not in " ".join(lines) and "The truth's cost" not in " ".join(lines)


@pytest.mark.parametrize(
    ("methods", "uncertainty", "said"),
    [
        (("kkt",), 40, "drawn for moirl and maxent fits only, and this run's method (kkt) has none"),
        (("kkt", "bilevel"), 40, "`--method moirl kkt bilevel`"),
        (("moirl",), 40, "though they were asked for (`uncertainty = 40`)"),
        (("moirl",), 0, "rerun with `--uncertainty` to quote a share"),
    ],
)
def test_a_run_without_weight_samples_says_why(methods, uncertainty, said):
    # reproduce --method kkt --uncertainty 40 told the reader to rerun with --uncertainty, which it had
    from types import SimpleNamespace

    from reachirl.experiments.cost import cost_section

    run = SimpleNamespace(results={}, config=SimpleNamespace(methods=methods, uncertainty=uncertainty))
    text = " ".join(cost_section(run))
    assert said in text
    assert ("rerun with `--uncertainty`" in text) == (uncertainty == 0)


def test_the_fits_warnings_reach_the_report_notes_with_the_units_they_came_from():
    from reachirl.experiments.protocol import ProtocolConfig
    from reachirl.experiments.report import _notes

    def unit(key, warnings):
        return {
            "key": key,
            "fit": {"doc_solves": 10, "doc_failures": 0},
            "evaluation": {"doc_solves": 5, "doc_failures": 0},
            "stop_reason": "converged",
            "unit": {"method": "bilevel", "observe": False},
            "weights": [[1.0] * 7],
            "warnings": warnings,
        }

    budget = "stopped at its budget of 400 DOC solves (max_evals) after 3 complete iterations"
    results = {k: unit(k, w) for k, w in (("bilevel-P2-s1", [budget]), ("bilevel-P4-s1", [budget]), ("x", []))}
    notes, _ = _notes(results, ProtocolConfig())
    (line,) = [n for n in notes if n.startswith("Fit warnings")]
    assert line == f"Fit warnings (also in each model's `info.warnings`): bilevel-P2-s1, bilevel-P4-s1: {budget}."
    quiet, _ = _notes({"x": unit("x", [])}, ProtocolConfig())
    assert not [n for n in quiet if n.startswith("Fit warnings")]
    # --max-iter is MO-IRL's: a run of baselines alone says how they stop instead
    (ended,) = [n for n in notes if n.startswith("Fits ended by")]
    assert f"at most {ProtocolConfig().max_iter} iterations per stage" in ended
    (baselines,) = [n for n in _notes(results, ProtocolConfig(methods=("bilevel", "kkt")))[0] if "ended by" in n]
    assert "iterations per stage" not in baselines and "not at --max-iter" in baselines


@pytest.mark.parametrize(
    ("options", "said"),
    [
        (
            {},
            "learn from 10 trial(s) of subject S1 chosen at random (seed 0) (when a posture has fewer, all of them), "
            "cross-validate on its other trials,",
        ),
        # --train-side with --cv rest: the training and CV trials are of that arm only (the report did not say so)
        (
            {"train_side": "left"},
            "learn from 10 trial(s) of subject S1 (left arm) chosen at random (seed 0) (when a posture has fewer, "
            "all of them), cross-validate on its other left-arm trials (its other arm's are not used),",
        ),
        (
            {"cv": "other-side"},
            "(right arm) chosen at random (seed 0) (when a posture has fewer, all of them), "
            "cross-validate on its other-arm reaches (mirrored),",
        ),
        # --n-train 0 takes every trial: no "when a posture has fewer"
        (
            {"n_train": None, "cv": "other-side", "train_side": "left"},
            "learn from all the trials of subject S1 (left "
            "arm), cross-validate on its other-arm reaches (mirrored), ISCV",
        ),
    ],
)
def test_the_protocol_line_names_the_arm_the_training_takes(options, said):
    assert said in protocol_line(ProtocolConfig(**options), "S1", ["P2"])


def test_the_cost_section_counts_as_undetermined_what_it_says_it_counts():
    """'shares undetermined' counted the narrow shares whose interval misses the fit's own share (as `fit`, the
    figures and docs/usage.md say), but the report's text defined it as the intervals wider than 0.25 alone: a
    reader seeing every interval narrow and "50 %" could not tell why."""
    from types import SimpleNamespace

    from reachirl.experiments.cost import cost_section

    low, high = np.zeros((1, 7)), np.full((1, 7), 0.2)  # every interval narrow
    determined = np.ones((1, 7), bool)
    determined[0, :3] = False  # three of them miss the fit's share (a 7-feature window: 43 %)
    unc = {
        "determination": {"n_determined": 0, "n_directions": 7, "determined": []},
        "share_intervals": {"low": low.tolist(), "high": high.tolist(), "determined": determined.tolist()},
        "prior": {"mean_width": 0.99, "claim_fraction": None},
        "claim": {"verdict": "not applicable", "fraction": None},
        "checked": {"solved": 10, "indistinguishable": 0},
    }
    run = SimpleNamespace(
        results={"moirl-P1-s1": {"key": "moirl-P1-s1", "unit": {"posture": "P1"}, "uncertainty": unc}}
    )
    lines = cost_section(run)
    (row,) = [line for line in lines if line.startswith("| moirl-P1-s1 |")]
    assert "| 43 % |" in row
    assert "wider than 0.25 or does not contain the fit's own share (undetermined" in " ".join(lines)


def test_a_run_without_weight_samples_says_nothing_is_hatched():
    """`reproduce --uncertainty 0`: fig3's caption in report.md said "Hatched: undetermined ..." over a figure
    with no hatching, and the figure sent the reader to `fit --uncertainty`, not the command that drew it."""
    from reachirl.experiments import figures as fg

    shares = {("P1", 1): np.full((1, 7), 1 / 7), ("P1", 8): np.full((8, 7), 1 / 7)}
    caption = weights_caption(shares, {})
    assert "Hatched" not in caption and "Nothing is hatched: the fits shown have no weight samples" in caption, caption
    assert "intervals bracket" not in caption  # no intervals were drawn
    assert "Hatched: undetermined" in weights_caption(
        shares, {k: _intervals(v, np.ones_like(v)) for k, v in shares.items()}
    )
    assert "fit or reproduce" in fg.NO_SAMPLES and "nothing is hatched" in fg.NO_SAMPLES


def test_the_methods_figure_says_what_its_bars_and_error_bars_are():
    """methods.png had ticks "Training 8" (8 what?) and error bars no caption or axis explained."""
    from reachirl.experiments import figures as fg

    cell = {"mean": 4.0, "std": 1.0}
    heads = {m: {s: {8: cell} for s in ("train", "cv", "iscv")} for m in ("moirl", "maxent")}
    fig = fg.plot_methods(heads, [8])
    ax = fig.axes[0]
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    assert ticks == ["Training · 8 sections", "CV · 8 sections", "ISCV · 8 sections"]
    assert "mean ± SD" in ax.get_ylabel()
    import inspect

    from reachirl.experiments import report

    assert "bars the mean, error bars ± the SD " in inspect.getsource(report.figure_jobs)


def test_a_convergence_panel_of_one_iteration_ticks_whole_iterations():
    """UE-ADL's 1-section fit accepted no step in its observed stage: its panel's x axis spanned -0.05..0.05 with
    ticks -0.045, -0.030, ... printed over each other. Now whole iterations around the point."""
    hist = {
        ("forward", 1): [{"iteration": 0, "merit": 1.2}],
        ("forward", 8): [{"iteration": 0, "merit": 0.8}, {"iteration": 2, "merit": 0.7}],
    }
    fig = fg.plot_convergence(hist, [1, 8])
    fig.canvas.draw()
    one, eight = fig.axes[:2]
    ticks = [t for t in one.get_xticks() if one.get_xlim()[0] <= t <= one.get_xlim()[1]]
    assert ticks and all(float(t).is_integer() for t in ticks), ticks
    assert eight.get_xlim()[1] - eight.get_xlim()[0] < 3  # a panel of several iterations keeps its own span


def test_the_merits_log_axis_is_labelled_in_plain_numbers_on_matplotlibs_own_ticks():
    """0.6 rather than 6 × 10⁻¹ (typeset as mathematical text, whose parser cost a figure worker a tenth of a
    second): the same ticks labelled as matplotlib's own log formatter labels them, only the text differs."""
    import matplotlib.pyplot as plt

    hist = {("P1", 6): [{"iteration": i, "merit": m} for i, m in enumerate([0.62, 0.31, 0.12, 0.093])]}
    fig = fg.plot_convergence(hist, [6])
    fig.canvas.draw()
    ax = fig.axes[0]
    ours = [(t.get_text(), t.get_position()[1]) for t in ax.get_yticklabels(which="both") if t.get_text()]
    ax.set_yscale("log")  # matplotlib's own formatters back, on the same limits
    ax.set_ylim(*ax.get_ylim())
    fig.canvas.draw()
    theirs = [t.get_position()[1] for t in ax.get_yticklabels(which="both") if t.get_text()]
    plt.close(fig)
    assert [y for _, y in ours] == pytest.approx(theirs) and len(ours) >= 4
    assert [text for text, _ in ours] == [f"{y:g}" for _, y in ours] and not any("$" in t for t, _ in ours)


def test_the_iscv_figure_draws_every_trials_measured_and_predicted_curves_in_degrees():
    """fig4_iscv draws each posture's trials as line collections (a study's panel holds hundreds): every trial's
    measured curve dashed and its prediction solid, per joint, in degrees over normalised time, inside the axes."""
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(0)
    n_trials, n_pts = 3, 7
    arrays = {"iscv/t": np.tile(np.linspace(0.0, 1.2, n_pts), (n_trials, 1))}
    for who in ("demo", "pred"):
        for kind in ("q", "qd"):
            arrays[f"iscv/{who}_{kind}"] = rng.normal(size=(n_trials, n_pts, 2))
    fig = fg.plot_iscv({"P2": arrays})
    s = np.linspace(0.0, 1.0, n_pts)
    for row, kind in enumerate(("q", "qd")):
        ax = fig.axes[row]
        drawn = ax.collections
        assert len(drawn) == 4  # per joint: the measured curves, then the predicted ones
        for c, (j, who) in zip(drawn, [(j, w) for j in range(2) for w in ("demo", "pred")], strict=True):
            want = np.rad2deg(arrays[f"iscv/{who}_{kind}"][..., j])
            segs = c.get_segments()
            assert len(segs) == n_trials
            for i in range(n_trials):
                np.testing.assert_array_equal(segs[i][:, 0], s)
                np.testing.assert_allclose(segs[i][:, 1], want[i])
            assert (c.get_linestyle()[0][1] is None) == (who == "pred")  # dashed measured, solid predicted
        lo, hi = ax.get_ylim()
        every = np.rad2deg(np.concatenate([arrays[f"iscv/{w}_{kind}"].ravel() for w in ("demo", "pred")]))
        assert lo <= every.min() and every.max() <= hi
    plt.close(fig)


def test_the_figures_feature_labels_are_the_features_names_shortened():
    """The figures said "torque" for joint_torque (misread as torque change) and "fingertip vel." for
    cartesian_velocity, while the report, MODEL.json and FEATURES say the names: each label's words are now the
    name's words, cut short at most."""
    from reachirl.experiments.figures import SHORT

    assert set(SHORT) == set(FEATURES)
    for name, label in SHORT.items():
        words, said = name.split("_"), label.lower().replace(".", "").split()
        assert len(said) == len(words) and all(w.startswith(s) for w, s in zip(words, said, strict=True)), label
