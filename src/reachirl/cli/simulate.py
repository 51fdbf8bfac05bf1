"""``reachirl simulate --model MODEL.json TRIALS [--render OUT.gif] [--trial ID|INDEX ...] [--backend B]
[--mode M]``.

``--subject/--posture/--side`` select trials of TRIALS, and ``--trial`` picks among the selected ones: by id,
trial_id or index (the N-th selected trial, 0-based; ``--posture P2 --trial 0`` is the file's first P2 trial).

Predicts each chosen trial with the learned weights as evaluate does (the same reach whose RMSE evaluate
reports), plays the prediction's torques back in MuJoCo (open loop or with PD tracking) and prints how far
MuJoCo's reach drifts from the DOC's; optionally renders the reaches (the demonstrations as translucent ghosts,
on the same normalised time) to a GIF or MP4. A prediction whose DOC did not converge is played and reported,
but left out of the summary over trials.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from . import SUMMARIES
from ._args import (
    ANIMATION_KINDS,
    JSON_KINDS,
    PREDICTION_BACKEND_HELP,
    add_selection,
    file_path,
    int_in,
    number_in,
    picked_trials,
    refuse_overwrite,
    same_file,
)

BACKENDS = ("casadi", "crocoddyl")
MAX_RENDER_BYTES = 1024**3  # frames of an animation, all in memory (and GIF encoding time grows with them)
MODES = ("open-loop", "pd")


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "simulate",
        help=SUMMARIES["simulate"],
        description=__doc__.replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", type=Path, required=True, help="model JSON written by `reachirl fit`")
    p.add_argument(
        "trials",
        type=Path,
        help="trials file (NPZ) written by `reachirl preprocess` (from recordings, `reachirl synth`'s too)",
    )
    p.add_argument(
        "--render",
        type=Path,
        default=None,
        metavar="OUT.gif",
        help="write an animation, .gif or .mp4 (H.264); a file already there is replaced only when it is a GIF or "
        "MP4 as named (default: none)",
    )
    p.add_argument(
        "--trial",
        action="append",
        default=None,
        metavar="ID|INDEX",
        help="a trial to simulate, among those --subject/--posture/--side select: by id (subject/posture/side/"
        "trial), trial_id or 0-based index among the selected trials; repeat for several (default: every selected "
        "trial)",
    )
    add_selection(p, "simulate")
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default=None,
        help=PREDICTION_BACKEND_HELP,
    )
    p.add_argument("--mode", choices=MODES, default="open-loop", help="torque playback (default open-loop)")
    p.add_argument(
        "--substeps",
        type=int_in(1, 1000),
        default=None,
        help="MuJoCo steps per DOC interval, 1 to 1000 (default 10, or with --mode pd the fewest from 10 up at "
        "which --kp and --kd integrate stably)",
    )
    p.add_argument(
        "--kp",
        type=number_in(0.0, 1e5),
        default=None,
        help="with --mode pd: PD stiffness, N·m/rad, 0 to 1e5 and at most I/h² for MuJoCo's step h and the arm's "
        "smallest inertia I (stated when exceeded) (default 50)",
    )
    p.add_argument(
        "--kd",
        type=number_in(0.0, 1e4),
        default=None,
        help="with --mode pd: PD damping, N·m·s/rad, 0 to 1e4 and at most I/h (stated when exceeded) (default 5)",
    )
    p.add_argument(
        "--fps",
        type=number_in(1.0, 120.0),
        default=None,
        help="with --render: animation frames per second of reach time, 1 to 120 (default 30)",
    )
    p.add_argument(
        "--size",
        type=int_in(16, 1280),
        default=None,
        help="with --render: animation width and height in pixels, 16 to 1280 (default 480)",
    )
    p.add_argument(
        "--out", type=file_path, default=None, metavar="SIM.json", help="also write the figures as JSON (default: none)"
    )
    return p


#: the defaults of the options that apply only with --mode pd (the gains) or with --render (the animation's): a
#: value given without them would be ignored, so it is refused (:func:`_check_mode_options`)
PD_DEFAULTS = {"kp": 50.0, "kd": 5.0}
RENDER_DEFAULTS = {"fps": 30.0, "size": 480}


def _check_mode_options(args: argparse.Namespace) -> None:
    """Refuse ``--kp``/``--kd`` without ``--mode pd`` and ``--fps``/``--size`` without ``--render`` (they were
    ignored without a word: an open-loop playback run for a PD one), then fill in their defaults."""
    for names, applies, needs in (
        (PD_DEFAULTS, args.mode == "pd", "--mode pd"),
        (RENDER_DEFAULTS, args.render is not None, "--render OUT.gif"),
    ):
        given = [n for n in names if getattr(args, n) is not None]
        if given and not applies:
            raise InputError(f"--{given[0]} applies only with {needs}; without it the option would be ignored")
        for n, default in names.items():
            if getattr(args, n) is None:
                setattr(args, n, default)


def _stretch(model) -> float:
    """How much longer than its trial the reach played can last: an observed model plays the DOC's part above
    the onset threshold, at most the rest-to-rest horizon ``duration / MOVING_FRACTION``."""
    from ..doc.observation import MOVING_FRACTION

    return 1.0 / MOVING_FRACTION if model.observe else 1.0


def _pd_substeps(args, trials, n_nodes: int, stretch: float = 1.0) -> int:
    """The fewest MuJoCo steps per DOC interval, from 10 up, at which the PD gains integrate stably on these arms
    (at most 1000; :func:`_check_gains` then says what is still too large)."""
    from ..data.checks import pd_gain_limits

    substeps = 10
    while substeps < 1000:
        kp_max, kd_max, _, _ = pd_gain_limits(trials, n_nodes, substeps, stretch)
        if args.kp <= kp_max and args.kd <= kd_max:
            break
        substeps = min(1000, substeps + max(1, substeps // 4))
    return substeps


def _check_gains(args, trials, n_nodes: int, stretch: float = 1.0) -> None:
    """PD gains that MuJoCo's explicit step integrates stably on these arms
    (:func:`reachirl.data.checks.pd_gain_limits`); larger ones make the playback diverge."""
    from ..data.checks import pd_gain_limits

    kp_max, kd_max, h, inertia = pd_gain_limits(trials, n_nodes, args.substeps, stretch)
    why = (
        f"the largest that MuJoCo's step of {1000 * h:.3g} ms integrates stably on this arm (smallest inertia "
        f"{inertia:.3g} kg·m²); lower it or raise --substeps"
    )
    if args.kd > kd_max:
        raise InputError(f"--kd {args.kd:g} N·m·s/rad is outside [0, {kd_max:.3g}], {why}", args.trials)
    if args.kp > kp_max:
        raise InputError(f"--kp {args.kp:g} N·m/rad is outside [0, {kp_max:.3g}], {why}", args.trials)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ..data.checks import check_model_rollout
    from ..data.trial import load_trials
    from ..io import atomic_write_json
    from ..irl.model import load_model

    try:
        from ..sim import simulate as sim
        from ..sim.render import render_available
    except RuntimeError as e:  # MuJoCo refuses an unknown MUJOCO_GL as it is imported: the user's setting
        if "MUJOCO_GL" not in str(e):
            raise
        raise InputError(f"{e} (MuJoCo takes osmesa, egl or glfw here; unset, osmesa without a display)") from None
    from ..validation import check_output_file, check_output_kind

    _check_mode_options(args)
    if args.render is not None and args.render.suffix.lower() not in ANIMATION_KINDS:
        raise InputError("the animation must end in .gif or .mp4", args.render)
    for opt, path in (("--out", args.out), ("--render", args.render)):
        if path is not None:
            check_output_file(path, opt)
    refuse_overwrite({"--out": args.out, "--render": args.render}, [args.model, args.trials])
    check_output_kind(args.out, ".json", kind=JSON_KINDS["simulate"])
    if args.render is not None:  # an animation replaces an animation, never a file of the user's named so
        suffix = args.render.suffix.lower()
        check_output_kind(args.render, suffix, "--render", ANIMATION_KINDS[suffix])
    if args.out is not None and args.render is not None and same_file(args.out, args.render):
        raise InputError("--render and --out are the same file; give each its own", args.render)
    if args.render is not None:  # before any work: a missing OpenGL is the machine's, said in one line
        ok, why = render_available()
        if not ok:
            raise InputError(
                f"--render: cannot render offscreen here: {why} (without --render the playback runs alone)",
                args.render,
            )
    model = load_model(args.model)
    check_model_rollout(model, args.model)
    backend = args.backend or model.backend
    trials = picked_trials(args, load_trials(args.trials), args.trials)
    stretch = _stretch(model)
    if args.substeps is None:
        args.substeps = _pd_substeps(args, trials, model.n_nodes, stretch) if args.mode == "pd" else 10
    if args.mode == "pd":
        _check_gains(args, trials, model.n_nodes, stretch)
    if args.render is not None:  # every frame is held in memory until the file is written
        n_frames = sum(int(stretch * tr.duration * args.fps) + int(0.5 * args.fps) + 2 for tr in trials)
        n_bytes = n_frames * args.size * args.size * 3
        if n_bytes > MAX_RENDER_BYTES:
            raise InputError(
                f"--render: {len(trials)} trial(s) at --fps {args.fps:g} and --size {args.size} make {n_frames} "
                f"frames ({n_bytes / 1024**3:.3g} GiB); choose fewer --trial, a lower --fps or a smaller --size "
                f"(at most {MAX_RENDER_BYTES / 1024**3:g} GiB)",
                args.render,
            )
    sims = []
    for tr in trials:
        s = sim.simulate_trial(
            tr,
            model.weights,
            n_nodes=model.n_nodes,
            backend=backend,
            mode=args.mode,
            substeps=args.substeps,
            kp=args.kp,
            kd=args.kd,
            observe=model.observe,
            path=model.rollout_q,
        )
        sims.append(s)
        r, d = s.result, s.solution
        print(
            f"{tr.id}: DOC ({d.backend}) {'converged' if d.converged else 'NOT converged'} in {d.iterations} "
            f"iterations, {d.solve_time:.2f} s; MuJoCo {r.mode} ({r.substeps} substeps): RMSE q "
            f"{r.rmse_deg['q']:.3f}° (q1 {r.rmse_deg['q1']:.3f}°, q2 {r.rmse_deg['q2']:.3f}°), "
            f"max {r.max_abs_deg:.3f}°, final fingertip x error {1000 * r.final_x_error:+.2f} mm"
        )
    kept = [s for s in sims if s.solution.converged]
    failed = len(sims) - len(kept)
    if len(sims) > 1 or failed:
        left_out = f"; {failed} DOC failure(s) left out" if failed else ""
        if kept:
            rm = np.array([s.result.rmse_deg["q"] for s in kept])
            fx = np.array([abs(s.result.final_x_error) for s in kept])
            n = f"{len(kept)} of {len(sims)}" if failed else f"{len(sims)}"
            print(
                f"{n} trials: RMSE q {rm.mean():.3f} ± {rm.std():.3f}°, |final x error| "
                f"{1000 * fx.mean():.2f} ± {1000 * fx.std():.2f} mm{left_out}"
            )
        else:
            print(f"0 of {len(sims)} trials: every DOC failed, no summary{left_out}")
    if args.out is not None and args.render is not None:  # an earlier run's pair goes first: an interrupt never
        for path in (args.out, args.render):  # leaves one beside the other (each alone is replaced atomically)
            Path(path).unlink(missing_ok=True)
    if args.render is not None:
        path, n_frames = sim.render_simulations(sims, args.render, fps=args.fps, width=args.size, height=args.size)
        print(f"wrote {path} ({n_frames} frames)")
    if args.out is not None:
        atomic_write_json(
            args.out,
            {
                "backend": backend,
                "mode": args.mode,
                "substeps": args.substeps,
                "doc_failures": failed,
                "trials": [s.summary() for s in sims],
            },
        )
        print(f"wrote {args.out}")
    return 0
