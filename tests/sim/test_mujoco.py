"""MuJoCo playback: the MJCF arm has the same dynamics, open-loop playback reproduces the DOC, rendering, CLI."""

import json

import numpy as np
import pytest

from reachirl import ReachingTask, solve_doc
from reachirl.cli import main
from reachirl.data.trial import Trial, save_trials
from reachirl.irl.model import LearnedModel, save_model

mujoco = pytest.importorskip("mujoco")
from reachirl.sim import arm_mujoco_model, playback  # noqa: E402
from reachirl.sim.render import osmesa_available  # noqa: E402

PHI_SCALE = np.array([0.5, 3.0, 0.3, 60.0, 100.0, 3.0, 40.0])


@pytest.fixture(scope="module")
def reach(arm):
    task = ReachingTask(arm, np.deg2rad([-60.0, 90.0]), 0.95 * arm.length, 0.7, 60)
    sol = solve_doc(task, np.ones((1, 7)) / PHI_SCALE)
    assert sol.converged
    return task, sol


def test_mass_matrix_and_bias_match_pinocchio_and_closed_form(arm, rng):
    pin = pytest.importorskip("pinocchio")
    model = arm_mujoco_model(arm, 0.005, 0.6)
    data = mujoco.MjData(model)
    pmodel = arm.pinocchio_model()
    pdata = pmodel.createData()
    M = np.zeros((2, 2))
    for _ in range(10):
        q, qd = rng.uniform(-np.pi, np.pi, 2), rng.uniform(-8, 8, 2)
        data.qpos[:], data.qvel[:] = q, qd
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, M)
        np.testing.assert_allclose(M, arm.mass_matrix(q), atol=1e-9)
        np.testing.assert_allclose(M, pin.crba(pmodel, pdata, q), atol=1e-9)
        np.testing.assert_allclose(data.qfrc_bias, arm.bias(q, qd), atol=1e-9)
        np.testing.assert_allclose(data.qfrc_bias, pin.nle(pmodel, pdata, q, qd), atol=1e-9)
        np.testing.assert_allclose(data.site_xpos[0][:2], arm.fk(q), atol=1e-12)


def test_open_loop_with_the_doc_timestep_reproduces_the_doc(arm, reach):
    _, sol = reach
    res, _ = playback(arm, sol, mode="open-loop", substeps=1)
    assert res.rmse_deg["q"] < 1e-6  # MuJoCo's Euler integrator is the DOC's semi-implicit Euler
    assert abs(res.final_x_error) < 1e-9


def test_substeps_drift_and_pd_tracking(arm, reach):
    task, sol = reach
    open_loop, _ = playback(arm, sol, mode="open-loop", substeps=10)
    pd, trace = playback(arm, sol, mode="pd", substeps=10, record=True)
    assert 0 < open_loop.rmse_deg["q"] < 3.0
    assert pd.rmse_deg["q"] < open_loop.rmse_deg["q"]
    assert abs(pd.final_x_error) < 0.01
    assert trace.shape == (task.n_nodes * 10 + 1, 2)
    with pytest.raises(ValueError, match="mode"):
        playback(arm, sol, mode="closed")


def _trials_file(arm, tmp_path, n_nodes=40):
    trials = []
    for i, q0 in enumerate(([-60.0, 90.0], [0.0, 90.0])):
        task = ReachingTask(arm, np.deg2rad(q0), 0.95 * arm.length, 0.7, n_nodes)
        sol = solve_doc(task, np.exp(np.random.default_rng(i).normal(0, 0.4, (1, 7))) / PHI_SCALE)
        qdd = np.vstack([np.diff(sol.qd, axis=0) / task.dt, np.zeros((1, 2))])
        trials.append(
            Trial(
                "S1",
                f"P{i + 1}",
                str(i),
                sol.t,
                sol.q,
                sol.qd,
                qdd,
                arm.inverse_dynamics(sol.q, sol.qd, qdd),
                task.target_x,
                arm,
            )
        )
    save_trials(tmp_path / "trials.npz", trials)
    save_model(tmp_path / "model.json", LearnedModel(np.ones((2, 7)) / PHI_SCALE, n_nodes=n_nodes))
    return tmp_path / "trials.npz", tmp_path / "model.json"


def test_simulate_cli_renders_a_gif(arm, tmp_path, capsys):
    ok, why = osmesa_available()
    if not ok:
        pytest.skip(why)
    import imageio.v3 as iio

    trials, model = _trials_file(arm, tmp_path)
    out = tmp_path / "sim.gif"
    rc = main(
        [
            "simulate",
            "--model",
            str(model),
            str(trials),
            "--render",
            str(out),
            "--trial",
            "1",
            "--mode",
            "pd",
            "--out",
            str(tmp_path / "sim.json"),
            "--size",
            "160",
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "S1/P2/right/1" in text and "RMSE q" in text and "final fingertip x error" in text
    frames = iio.imread(out, index=None)
    assert frames.shape[0] >= 10 and frames.shape[1:3] == (160, 160)
    assert f"wrote {out} ({frames.shape[0]} frames)" in text  # the count announced is the count in the file
    last = frames[-1][..., :3].astype(int)
    blue = (last[..., 2] > 150) & (last[..., 0] < 120)  # the simulated arm
    red = (last[..., 0] > 180) & (last[..., 1] < 110) & (last[..., 2] < 110)  # the target bar
    orange = (last[..., 0] > 180) & (last[..., 1] > 90) & (last[..., 1] < 190) & (last[..., 2] < 90)  # the ghost
    assert blue.sum() > 50 and red.sum() > 50 and orange.sum() > 10
    assert (tmp_path / "sim.json").exists()


def test_simulate_cli_bad_trial_is_exit_2(arm, tmp_path, capsys):
    trials, model = _trials_file(arm, tmp_path)
    assert main(["simulate", "--model", str(model), str(trials), "--trial", "9"]) == 2
    assert "index out of range" in capsys.readouterr().err
    assert main(["simulate", "--model", str(model), str(trials), "--render", str(tmp_path / "x.png")]) == 2
    capsys.readouterr()
    assert main(["simulate", "--model", str(model), str(trials), "--subject", "S9"]) == 2
    err = capsys.readouterr().err
    assert "S9" in err and str(trials) in err and len(err.strip().splitlines()) == 1


def test_simulate_chooses_trials_as_fit_evaluate_and_plot_do(arm, tmp_path, capsys):
    trials, model = _trials_file(arm, tmp_path)
    out = tmp_path / "sim.json"
    assert main(["simulate", "--model", str(model), str(trials), "--posture", "P2", "--out", str(out)]) == 0
    assert [t["id"] for t in json.loads(out.read_text())["trials"]] == ["S1/P2/right/1"]
    # --trial's index counts among the selected trials: the first P2 one, though trial_id "0" is P1's
    p2, out = ["simulate", "--model", str(model), str(trials), "--posture", "P2"], tmp_path / "first_p2.json"
    assert main([*p2, "--trial", "0", "--out", str(out)]) == 0
    assert [t["id"] for t in json.loads(out.read_text())["trials"]] == ["S1/P2/right/1"]
    capsys.readouterr()
    assert main([*p2, "--trial", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        f"{trials}: --trial 2: index out of range, expected 0 to 0 (the selection --posture P2 holds 1 of the "
        "file's 2 trials)"
    )


def test_simulate_plays_a_trial_named_twice_once(arm, tmp_path, capsys):
    # by index and by id: one reach, not two in SIM.json and in the summary over trials
    trials, model = _trials_file(arm, tmp_path)
    out = tmp_path / "sim.json"
    argv = ["simulate", "--model", str(model), str(trials), "--posture", "P2", "--out", str(out)]
    assert main([*argv, "--trial", "0", "--trial", "S1/P2/right/1", "--trial", "0"]) == 0
    assert [t["id"] for t in json.loads(out.read_text())["trials"]] == ["S1/P2/right/1"]
    assert " trials: RMSE q" not in capsys.readouterr().out  # one trial: no summary over trials
    assert (
        main(["simulate", "--model", str(model), str(trials), "--trial", "1", "--trial", "0", "--out", str(out)]) == 0
    )
    assert [t["id"] for t in json.loads(out.read_text())["trials"]] == ["S1/P2/right/1", "S1/P1/right/0"]


@pytest.mark.parametrize("sex", ["M", "F"])
def test_mjcf_compiles_for_any_body_size(sex):
    """MuJoCo checks A + B >= C on each inertia; exact halves failed after rounding for some subjects."""
    from reachirl import ArmModel

    rng = np.random.default_rng(1)
    for _ in range(25):
        arm = ArmModel.from_anthropometrics(
            rng.uniform(1.5, 2.0),
            rng.uniform(45, 110),
            sex,
            upper_arm_m=rng.uniform(0.22, 0.34),
            forearm_m=rng.uniform(0.2, 0.3),
            hand_m=rng.uniform(0.15, 0.21),
        )
        model = arm_mujoco_model(arm, 0.005, 0.9 * arm.length)
        assert model.nv == 2


def test_simulate_renders_an_mp4_through_the_console_script(arm, tmp_path, cli):
    ok, why = osmesa_available()
    if not ok:
        pytest.skip(why)
    import imageio

    trials, model = _trials_file(arm, tmp_path)
    out = tmp_path / "reach.mp4"
    proc = cli("simulate", "--model", model, trials, "--trial", "0", "--render", out, "--size", "161")
    assert proc.returncode == 0, proc.stderr
    reader = imageio.get_reader(out, format="FFMPEG")
    try:
        n = reader.count_frames()
        frame = reader.get_data(0)
    finally:
        reader.close()
    assert f"wrote {out} ({n} frames)" in proc.stdout and n >= 10
    assert frame.shape == (162, 162, 3) and frame.std() > 5  # odd sizes padded to even (H.264); not blank


def test_pd_playback_takes_the_substeps_its_default_gains_need(arm, tmp_path, capsys):
    """Few knots make a DOC interval long; the default gains then need more MuJoCo steps per interval than 10,
    which the default takes (an explicit --substeps stays the user's, and is refused when too few)."""
    trials, model = _trials_file(arm, tmp_path, n_nodes=20)
    out = tmp_path / "sim.json"
    args = ["simulate", "--model", str(model), str(trials), "--trial", "0", "--mode", "pd"]
    assert main([*args, "--substeps", "10"]) == 2
    assert "--kd 5 N·m·s/rad is outside" in capsys.readouterr().err
    assert main([*args, "--out", str(out)]) == 0
    substeps = json.loads(out.read_text())["substeps"]
    assert substeps > 10
    assert main([*args, "--substeps", str(substeps), "--out", str(tmp_path / "same.json")]) == 0


def test_pd_gain_limits_hold_for_the_longest_step_and_the_reach_played(arm, tmp_path):
    """The gains must integrate stably at every trial's step: the longest trial's (the least stable), and for an
    observed model the longest the reach played can be (the rest-to-rest horizon, duration / 0.9)."""
    from dataclasses import replace

    from reachirl.data.checks import pd_gain_limits
    from reachirl.data.trial import load_trials

    trials_file, _ = _trials_file(arm, tmp_path)
    short = load_trials(trials_file)[0]
    long = replace(short, t=2.0 * short.t)
    kp, _, h, inertia = pd_gain_limits([short, long], 40, 10)
    assert h == pytest.approx(long.duration / 400) and kp == pytest.approx(inertia / h**2)
    assert pd_gain_limits([long, short], 40, 10)[2] == h  # whatever the order
    assert pd_gain_limits([short, long], 40, 10, stretch=1 / 0.9)[2] == pytest.approx(h / 0.9)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--kp", "80"], r"--kp applies only with --mode pd; without it the option would be ignored"),
        (["--mode", "open-loop", "--kd", "2"], r"--kd applies only with --mode pd"),
        (["--fps", "10"], r"--fps applies only with --render OUT\.gif"),
        (["--out", "sim.json", "--size", "160"], r"--size applies only with --render OUT\.gif"),
    ],
)
def test_options_of_another_mode_are_refused_not_ignored(extra, match):
    """--kp/--kd without --mode pd and --fps/--size without --render changed nothing (an open-loop playback was
    run for the PD one asked for); they are refused, and their defaults hold where they apply."""
    from reachirl.cli import build_parser
    from reachirl.cli.simulate import _check_mode_options
    from reachirl.errors import InputError

    parse = build_parser().parse_args
    with pytest.raises(InputError, match=match):
        _check_mode_options(parse(["simulate", "--model", "m.json", "t.npz", *extra]))
    args = parse(["simulate", "--model", "m.json", "t.npz", "--mode", "pd", "--render", "a.gif", "--kd", "2"])
    _check_mode_options(args)
    assert (args.kp, args.kd, args.fps, args.size) == (50.0, 2.0, 30.0, 480)


def test_simulate_refuses_pd_gains_for_an_open_loop_playback(arm, tmp_path, capsys):
    trials, model = _trials_file(arm, tmp_path)
    out = tmp_path / "sim.json"
    assert main(["simulate", "--model", str(model), str(trials), "--trial", "0", "--kp", "80", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--kp applies only with --mode pd" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_render_unavailable_is_one_line_exit_2_before_any_work(arm, tmp_path, capsys, monkeypatch):
    """No OSMesa (or no OpenGL context of MUJOCO_GL's backend) is the machine's, not reachirl's: --render is refused
    before a DOC is solved, exit 2 in one line naming the animation and why (it was an internal error, exit 1)."""
    import reachirl.sim.render as render

    trials, model = _trials_file(arm, tmp_path)
    why = "libOSMesa cannot be loaded (libOSMesa.so.8: cannot open shared object file); install Debian's libosmesa6"
    monkeypatch.setattr(render, "osmesa_available", lambda: (False, why))
    out = tmp_path / "reach.gif"
    assert main(["simulate", "--model", str(model), str(trials), "--trial", "0", "--render", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and f"{out}: --render: cannot render offscreen here: {why}" in err
    assert captured.out == "" and not out.exists()  # refused before the playback


def test_an_unknown_mujoco_gl_is_one_line_exit_2(arm, tmp_path, cli, monkeypatch):
    # MuJoCo refuses it as it is imported: an internal error (exit 1) before, with or without --render
    trials, model = _trials_file(arm, tmp_path)
    monkeypatch.setenv("MUJOCO_GL", "bogus")
    proc = cli("simulate", "--model", model, trials, "--trial", "0")
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "MUJOCO_GL: bogus" in err and "internal error" not in err
