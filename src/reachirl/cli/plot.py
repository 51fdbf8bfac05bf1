"""``reachirl plot --model MODEL.json TRIALS --out DIR`` or ``reachirl plot RUN_DIR --out DIR``: figures as PNG
and PDF.

With a model: ``--subject/--posture/--side`` choose the trials, and ``--trial`` picks among them (by id, trial_id
or index among the selected trials, 0-based); each is predicted from its own start exactly as ``evaluate`` predicts
it (the same function: the same RMSE, printed as ``evaluate`` prints it), and DIR gets ``prediction.png``
(demonstrations dashed against predictions solid, q and q̇ per joint), ``weights.png`` (each feature's share of its
window's cost on the fit's own reach, the shares its intervals bracket; undetermined shares hatched; a KKT model's
on the plotted trials: it solves no DOC) and
``convergence.png`` (the fit's merit per iteration, when the model file holds a history). With a
``reachirl reproduce`` folder: the run's figures (``fig2_prediction``, ``fig3_weights``, ``fig4_iscv``,
``convergence``, ``methods``) drawn again from its ``results.json`` and ``units/``. Every figure is written as
``.png`` and ``.pdf``, marked as reachirl's in its metadata; a file of DIR with a figure's name that does not carry
that mark (the user's own) is refused, never replaced, but in the run's own ``RUN_DIR/figures``, which holds what
``reproduce`` drew. DIR may be ``RUN_DIR`` itself or its ``figures`` folder, never one of the run's data folders
(``units``, ``models``, ``predictions``) nor a folder inside one: refused before any work. A ``RUN_DIR`` that a
command writes into now (a ``reproduce`` still running) is refused.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Mapping
from pathlib import Path

from ..errors import InputError
from ..io import holding_folder, reading_folder, sync_folder
from . import SUMMARIES
from ._args import (
    PREDICTION_BACKEND_HELP,
    add_selection,
    output_folder_files,
    picked_trials,
    refuse_foreign_figures,
    refuse_out_in_run_folders,
)


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "plot",
        help=SUMMARIES["plot"],
        description=__doc__.replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "source",
        type=Path,
        metavar="TRIALS|RUN_DIR",
        help="a trials file (with --model) or a folder written by `reachirl reproduce`",
    )
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        metavar="MODEL.json",
        help="model JSON written by `reachirl fit`, then SOURCE is a trials file (default: SOURCE is a run folder)",
    )
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the figures to")
    p.add_argument(
        "--trial",
        action="append",
        default=None,
        metavar="ID|INDEX",
        help="with --model: plot only this trial of those --subject/--posture/--side select (id, trial_id or "
        "0-based index among the selected trials); repeat for several (default: every selected trial)",
    )
    p.add_argument(
        "--backend",
        choices=("casadi", "crocoddyl"),
        default=None,
        help=f"with --model: {PREDICTION_BACKEND_HELP}",
    )
    p.add_argument("--no-pdf", action="store_true", help="write PNG only (default: PNG and PDF)")
    add_selection(p, "with --model: plot")
    return p


MODEL_FIGURES = ("prediction", "weights", "convergence")
"""The figures of ``plot --model``, by file stem."""


def _save(fig, out: Path, stem: str, pdf: bool, written: list[Path]) -> None:
    from ..experiments import figures as fg

    if pdf:
        fg.save(fig, out / f"{stem}.pdf", close=False)
        written.append(out / f"{stem}.pdf")
    fg.save(fig, out / f"{stem}.png")
    written.append(out / f"{stem}.png")


def model_figures(model, trials, errors, out: Path, pdf: bool = True, backend: str | None = None) -> list[Path]:
    """The figures of a learned model on trials, whose predictions and errors are ``errors``
    (:meth:`reachirl.irl.model.LearnedModel.evaluate` on ``backend``, by default the fit's; see the module
    docstring); returns the files written. The titles name the method, and the backends when not CasADi: the
    fit's beside the method, the predictions' when it is another."""
    import numpy as np

    from ..doc.evaluation import summarise
    from ..experiments import figures as fg
    from ..experiments.names import method_text
    from ..features import cost_shares

    n, n_nodes = model.n_windows, model.n_nodes
    written: list[Path] = []
    for stem in MODEL_FIGURES:  # an earlier set's figures go first: an interrupt or a figure not drawn never mixes
        for ext in ("png", "pdf"):
            (out / f"{stem}.{ext}").unlink(missing_ok=True)
    method = method_text(model.method, model.backend, bool(model.info.get("seed_form")))
    backend = backend or model.backend
    predicted = "predictions" if backend == model.backend else f"predictions on {backend}"  # not the fit's
    drawn = [(t, e) for t, e in zip(trials, errors, strict=True) if e.converged]  # a failed DOC is no prediction
    failed = len(errors) - len(drawn)
    rmse = summarise(errors)["rmse_deg"]["q"]["mean"]  # as `evaluate` reports it
    if drawn:
        demos = [t.resample(n_nodes + 1) for t, _ in drawn]
        arrays = {
            "trials/t": np.stack([e.prediction.t for _, e in drawn]),
            "trials/pred_q": np.stack([e.prediction.q for _, e in drawn]),
            "trials/pred_qd": np.stack([e.prediction.qd for _, e in drawn]),
            "trials/demo_t": np.stack([d.t for d in demos]),  # each on its own time: "time (s)" is true of both
            "trials/demo_q": np.stack([d.q for d in demos]),
            "trials/demo_qd": np.stack([d.qd for d in demos]),
        }
        left_out = f" ({failed} of {len(errors)} DOC failure(s) not drawn)" if failed else ""
        title = (
            f"{method}, {n} section{'s' if n > 1 else ''}: {len(drawn)} demonstration(s) (dashed) vs "
            f"{predicted} (solid){left_out}; mean RMSE of q {rmse:.2f}°"
        )
        _save(fg.plot_prediction(arrays, "trials", title=title), out, "prediction", pdf, written)
    shares = model.cost_shares()  # on the fit's own reach: the shares its intervals bracket
    unc = model.uncertainty
    note = None  # the figure's own caveat (with intervals, or what draws weight samples for the model's method)
    if shares is not None:
        label = "on the fit's own reach"
        undetermined = None if unc is None else {(label, n): ~np.asarray(unc["share_intervals"]["determined"], bool)}
    else:  # KKT (it solves no DOC) or a model file from before reach features were recorded: the chosen trials
        shares = cost_shares(model.weights, np.mean([t.features(n_nodes, n) for t in trials], axis=0))
        label, undetermined = f"on {len(trials)} recorded trial(s)", None
        why = "kkt solves no DOC: it has no reach of its own" if model.method == "kkt" else "no reach in the model file"
        note = f"Shares on the plotted trials' own features ({why}). " + (
            "The model's weight samples bracket the shares on its own reach, not these: nothing is hatched, and no "
            "share here is a finding."
            if unc is not None
            else fg.no_samples_note(model.method)
        )
    _save(
        fg.plot_weights(
            {(label, n): shares},
            [label],
            [n],
            undetermined=undetermined,
            title=f"{method}: each feature's share of its window's cost",
            note=note,
            method=model.method,
        ),
        out,
        "weights",
        pdf,
        written,
    )
    history = model.info.get("history") or []
    # MO-IRL and MaxEnt record iterations; bilevel's direct search records every DOC evaluation instead
    x_key = next((k for k in ("iteration", "evaluation") if any(h.get(k) is not None for h in history)), None)
    if x_key is not None and any(h.get("merit") is not None for h in history):
        from ..experiments.method import convergence_text

        options = model.info.get("options")  # every option in force, when the model file records them
        words = convergence_text(options if isinstance(options, Mapping) else {"observe": model.info.get("observe")})
        _save(
            fg.plot_convergence(
                {(method, n): history},
                [n],
                title=f"{method}: convergence" if x_key == "iteration" else f"{method}: merit of each evaluation",
                merit_label=words["merit_label"],
                start=words["start"],
                x_key=x_key,
            ),
            out,
            "convergence",
            pdf,
            written,
        )
    return written


@contextlib.contextmanager
def _malformed(res_path: Path):
    """A unit record of ``results.json`` that lacks a field or holds one of the wrong kind (a damaged or hand-edited
    file: its units are not checksummed as their checkpoints are) is an :class:`InputError` naming the file, not an
    internal error. Only the reading of the file's content runs under it: an error of the drawing itself is the
    program's, an internal error."""
    try:
        yield
    except InputError:
        raise
    except (KeyError, TypeError, IndexError, AttributeError, ValueError) as e:
        raise InputError(
            f"malformed results file ({type(e).__name__}: {str(e)[:120]}); rerun `reachirl reproduce` into the "
            "folder to write it again",
            res_path,
        ) from None


def run_figures(run_dir: Path, out: Path, pdf: bool = True) -> list[Path]:
    """A ``reproduce`` folder's figures drawn again from ``results.json`` and ``units/``; refused while a command
    writes into the folder (a ``reproduce`` running into it: what it holds is no finished run's), and such a
    command is refused while they are read and drawn (:func:`reachirl.io.reading_folder`)."""
    with reading_folder(run_dir):
        return _run_figures(run_dir, out, pdf)


def _run_figures(run_dir: Path, out: Path, pdf: bool) -> list[Path]:
    from dataclasses import fields

    from ..experiments import tables as tb
    from ..experiments.protocol import ProtocolConfig
    from ..experiments.rendering import drawing
    from ..experiments.report import figure_jobs
    from ..experiments.results import RunResult, RunSummary, check_results_file, protocol_config
    from ..io import read_json

    res_path = run_dir / "results.json"
    if not res_path.is_file():
        if (run_dir / "run.toml").is_file():  # a run stopped before its outputs (--max-units, an interrupt)
            raise InputError(
                "not a finished `reachirl reproduce` run: no results.json (rerun reproduce into it to finish)", run_dir
            )
        raise InputError("not a `reachirl reproduce` folder (no results.json)", run_dir)
    if not (run_dir / "table.csv").is_file():  # written last: the run stopped while writing its outputs
        raise InputError("not a finished `reachirl reproduce` run: no table.csv (rerun reproduce into it)", run_dir)
    d = read_json(res_path)
    if not isinstance(d, dict) or d.get("format") != "reachirl-reproduce/1" or "units" not in d:
        raise InputError("not a results file of `reachirl reproduce` (format reachirl-reproduce/1)", res_path)
    check_results_file(d, res_path)
    proto, units = d.get("protocol") or {}, d["units"]
    config = protocol_config({f.name: proto[f.name] for f in fields(ProtocolConfig) if f.name in proto}, res_path)
    results = {u["key"]: u for u in units}
    postures = list(proto.get("postures_run") or sorted({u["unit"]["posture"] for u in units}))
    sections, methods = list(config.sections), list(config.methods)
    with _malformed(res_path):
        tables = {m: tb.build_table(results, m, postures, sections) for m in methods}
    run = RunResult(
        out_dir=run_dir,
        dataset=None,
        config=config,
        postures=postures,
        train_subject="",
        split_sizes={},
        summary=RunSummary(results, [], list(results), False),
    )

    def draw(fig_dir: Path) -> dict:
        with _malformed(res_path):  # what each figure draws, read from the units
            jobs, figs = figure_jobs(run, tables, ({}, {}, {}), fig_dir=fig_dir, pdf=pdf)
        if out.resolve() != (run_dir / "figures").resolve():  # the run's own figures (a run of before the mark too)
            refuse_foreign_figures(out, _figure_files(figs, pdf), "--out")  # before drawing: replace reachirl's only
        with drawing(jobs):
            pass
        return figs

    return _drawn_whole(out, draw, pdf)


def _figure_files(figs, pdf: bool) -> list[str]:
    """The files of the figures ``figs`` (names as ``fig2_prediction.png``): a PNG each, and a PDF with ``pdf``."""
    return [f"{Path(n).stem}.{ext}" for n in figs for ext in (("png", "pdf") if pdf else ("png",))]


PARTIAL_PREFIX = ".plot-partial-"
"""The folder a run's figures are drawn in before they replace those in --out."""


def _drawn_whole(out: Path, draw, pdf: bool) -> list[Path]:
    """The figures ``draw(folder)`` writes, drawn in a hidden folder of ``out`` and moved into ``out`` only once
    every one is drawn: a figure that fails (a damaged results file) leaves ``out`` as it was, with no mix of new
    and earlier figures. A hidden folder a killed run left is removed first. ``draw`` refuses, before drawing, to
    replace a file that is not a figure of reachirl's (:func:`~._args.refuse_foreign_figures`)."""
    import os
    import shutil
    import tempfile

    made = not out.exists()
    # one command at a time in the folder: a second plot would remove this one's hidden folder while it draws
    with holding_folder(out, "--out") as make:
        make()
        try:
            for stale in out.glob(f"{PARTIAL_PREFIX}*"):
                shutil.rmtree(stale, ignore_errors=True)
            tmp = Path(tempfile.mkdtemp(prefix=PARTIAL_PREFIX, dir=out))
            try:
                names = _figure_files(draw(tmp), pdf)
                for n in names:
                    os.replace(tmp / n, out / n)  # each synced to the disk when drawn (atomic_path)
                from ..experiments.report import marked_run_figures

                for earlier in marked_run_figures(out, names):  # an earlier set's not drawn now: no mix of runs
                    earlier.unlink(missing_ok=True)
                sync_folder(out)  # and the renames
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
        except BaseException:  # a refusal (a damaged checkpoint) or a failure: no empty --out made for nothing
            if made:
                with contextlib.suppress(OSError):
                    out.rmdir()  # only when empty
            raise
    return [out / n for n in names]


#: the folders of a ``reproduce`` run that hold its data (checkpoints, models, exported predictions), which a rerun
#: reads, replaces or removes: no figure is written among them
RUN_DATA_FOLDERS = ("units", "models", "predictions")


def run(args: argparse.Namespace) -> int:
    from ..validation import check_output_dir

    out = check_output_dir(args.out)  # before any prediction: a folder in which files can be written
    if args.model is None and args.source.is_dir():  # a run's figures: never among its checkpoints or models
        refuse_out_in_run_folders(out, args.source, RUN_DATA_FOLDERS, "the figures", "figures")
    # one command at a time in the folder (from the start when it exists: refused before any work)
    with holding_folder(out, "--out") as make:
        return _plot(args, out, make)


def _plot(args: argparse.Namespace, out: Path, make_out) -> int:
    """The figures, once --out is held (if it exists); ``make_out()`` makes it and holds it."""
    if args.model is not None:
        from ..data.trial import load_trials
        from ..doc.evaluation import summarise
        from ..irl.model import load_model
        from .evaluate import summary_line

        if args.source.is_dir():
            raise InputError("is a folder; with --model, give a trials file", args.source)
        # the figures' files (an earlier set's go first) are never the model or the trials file read
        names = [f"{stem}.{ext}" for stem in MODEL_FIGURES for ext in ("png", "pdf")]
        output_folder_files(out, names, [args.model, args.source], "--out")
        refuse_foreign_figures(out, names, "--out")  # nor a file of the user's own that has their name
        model = load_model(args.model)
        trials = picked_trials(args, load_trials(args.source), args.source)
        errors = model.evaluate(trials, backend=args.backend)
        print(summary_line(summarise(errors), args.backend or model.backend))
        make_out()
        written = model_figures(model, trials, errors, out, pdf=not args.no_pdf, backend=args.backend)
    else:
        given = [o for o in ("subject", "posture", "side", "trial") if getattr(args, o) is not None]
        if given:
            raise InputError(
                f"--{given[0]} chooses trials, so it needs --model MODEL.json and a trials file", args.source
            )
        if args.backend is not None:  # a run's figures are drawn from its own predictions: none is solved again
            raise InputError(
                "--backend chooses the backend of the predictions of --model MODEL.json; a run's figures are "
                "drawn from its recorded predictions (rerun `reachirl reproduce --backend` for another backend)",
                args.source,
            )
        if not args.source.is_dir():
            raise InputError(
                "expected a `reachirl reproduce` folder (or give --model MODEL.json for a trials file)", args.source
            )
        written = run_figures(args.source, out, pdf=not args.no_pdf)
    for p in written:
        print(f"wrote {p}")
    return 0
