"""Nothing lost, nothing silently wrong (issue 34): an output never replaces an input, only regular files are
read, recordings are checked against their own headers, physically inconsistent inputs are refused at the door
(exit 2 naming the field and its range), checkpoints are verified by a checksum, errors name the file the user
passed, and an interrupt raised inside a solver ends the command instead of becoming a failed solve."""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import signal
import zipfile
from pathlib import Path

import numpy as np
import pytest

from reachirl.cli import main
from reachirl.cli._args import same_file
from reachirl.data.trial import load_trials, save_trials
from reachirl.errors import InputError, Terminated, solver_interrupts
from reachirl.irl.model import LearnedModel, save_model
from recordings import MARKERS, preprocess, synth


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """One virtual subject's P2 reaches as TRC (3 trials) and MOT (1 trial), their trials file and a model."""
    d = tmp_path_factory.mktemp("nothing_lost")
    synth(d / "syn", ("P2",), trials=2)
    synth(d / "mot", ("P2",), fmt="mot")
    preprocess(d / "syn", d / "trials.npz")
    save_model(d / "model.json", LearnedModel(weights=np.full((2, 7), 0.05), n_nodes=20))
    return d


def _digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _fails(argv, capsys, pattern: str) -> str:
    """``main(argv)`` exits 2 with one line on stderr matching ``pattern``."""
    import re

    code = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert len(err) == 1, err
    assert re.search(pattern, err[0]), err[0]
    return err[0]


# ---------------------------------------------------------------------- 1. inputs are never outputs
def _link(kind: str, src: Path, dst: Path) -> Path:
    if kind == "symlink":
        dst.symlink_to(src)
    elif kind == "hardlink":
        os.link(src, dst)
    else:
        return src
    return dst


@pytest.mark.parametrize("kind", ["same", "symlink", "hardlink"])
def test_preprocess_never_writes_over_a_recording(base, tmp_path, capsys, kind):
    trc = tmp_path / "victim.trc"
    shutil.copy(base / "syn" / "S01_P2_T01.trc", trc)
    before = _digest(trc)
    out = _link(kind, trc, tmp_path / "out.npz")
    _fails(
        ["preprocess", trc, "--markers", MARKERS, "--out", out],
        capsys,
        r"--out is the input file .*victim\.trc; it would be overwritten",
    )
    assert _digest(trc) == before


@pytest.mark.parametrize("which", ["manifest.csv", "subjects.csv"])
def test_preprocess_never_writes_over_its_manifest_or_subject_info(base, tmp_path, capsys, which):
    syn = tmp_path / "syn"
    shutil.copytree(base / "syn", syn)
    before = _digest(syn / which)
    _fails(
        [
            "preprocess",
            "--manifest",
            syn / "manifest.csv",
            "--subject-info",
            syn / "subjects.csv",
            "--markers",
            MARKERS,
            "--out",
            syn / which,
        ],
        capsys,
        rf"--out is the input file .*{which}",
    )
    assert _digest(syn / which) == before


@pytest.mark.parametrize(
    ("command", "which"), [("fit", "trials"), ("evaluate", "trials"), ("evaluate", "model"), ("simulate", "model")]
)
@pytest.mark.parametrize("kind", ["same", "symlink", "hardlink"])
def test_fit_evaluate_simulate_never_write_over_their_inputs(base, tmp_path, capsys, command, which, kind):
    trials, model = tmp_path / "t.npz", tmp_path / "m.json"
    shutil.copy(base / "trials.npz", trials)
    shutil.copy(base / "model.json", model)
    victim = trials if which == "trials" else model
    before = _digest(victim)
    out = _link(kind, victim, tmp_path / "o.json")
    argv = {
        "fit": ["fit", trials, "--sections", "1", "--nodes", "20", "--max-iter", "1", "--out", out],
        "evaluate": ["evaluate", "--model", model, trials, "--out", out],
        "simulate": ["simulate", "--model", model, trials, "--out", out],
    }[command]
    _fails(argv, capsys, rf"--out is the input file .*{victim.name}; it would be overwritten")
    assert _digest(victim) == before


def test_simulate_refuses_one_file_for_its_two_outputs(base, tmp_path, capsys):
    # the message once called the animation "the input file"
    out = tmp_path / "r.gif"
    argv = ["simulate", "--model", base / "model.json", base / "trials.npz", "--out", out, "--render", out]
    _fails(argv, capsys, r"r\.gif: --render and --out are the same file; give each its own$")
    assert not out.exists()


def _small_frames(monkeypatch) -> None:
    """simulate renders 3 frames of 16 × 16 pixels (MuJoCo's offscreen renderer is not needed)."""
    import reachirl.sim.simulate as sim

    frames = [np.full((16, 16, 3), 40 * k, dtype=np.uint8) for k in range(3)]
    monkeypatch.setattr(sim, "render_frames", lambda clips, **kw: list(frames))


def _animation(path: Path, suffix: str) -> Path:
    """A GIF or an MP4 of the user's own (or an earlier render) at ``path``."""
    import imageio.v3 as iio

    frames = np.stack([np.full((16, 16, 3), v, dtype=np.uint8) for v in (0, 200)])
    if suffix == ".gif":
        iio.imwrite(path, frames, duration=[100, 100], loop=0)
    else:
        iio.imwrite(path, frames, plugin="FFMPEG", fps=10, codec="libx264", macro_block_size=1)
    return path


@pytest.mark.parametrize(
    ("name", "content", "what"),
    [
        pytest.param("notes.gif", b"my notes, named .gif by mistake", "GIF animation", id="text"),
        pytest.param("clip.gif", b"\x89PNG\r\n\x1a\n" + bytes(64), "GIF animation", id="png"),
        pytest.param("clip.mp4", b"GIF89a" + bytes(64), "MP4 video", id="gif-named-mp4"),
        pytest.param("clip.mp4", b"", "MP4 video", id="empty"),
    ],
)
def test_simulate_render_never_replaces_a_file_that_is_not_an_animation(base, tmp_path, capsys, name, content, what):
    """--render replaced whatever was at its path: a file of the user's own that is not the GIF or MP4 its name
    says is refused before any work and left as it was."""
    existing = tmp_path / name
    existing.write_bytes(content)
    argv = ["simulate", "--model", base / "model.json", base / "trials.npz", "--render", existing]
    _fails(
        argv,
        capsys,
        rf"{re.escape(name)}: --render: exists and is not a {what} \(an earlier output of this command\); it would be "
        r"replaced \(choose another path, or remove it first\)$",
    )
    assert existing.read_bytes() == content


@pytest.mark.parametrize("which", ["trials", "model"])
def test_simulate_render_is_never_an_input(base, tmp_path, capsys, which):
    """--render through a symlink to an input (which would be replaced by the animation) is refused."""
    victim = base / ("trials.npz" if which == "trials" else "model.json")
    before = _digest(victim)
    render = _link("symlink", victim, tmp_path / "r.gif")
    argv = ["simulate", "--model", base / "model.json", base / "trials.npz", "--render", render]
    _fails(argv, capsys, rf"r\.gif: --render is the input file .*{victim.name}; it would be overwritten")
    assert _digest(victim) == before


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_simulate_render_replaces_an_animation_atomically(base, tmp_path, capsys, monkeypatch, suffix):
    """A GIF or MP4 at --render (an earlier render, or the user's own) is replaced, through a temporary file in the
    same folder: a render interrupted while written leaves the earlier animation as it was and no half file."""
    import imageio.v3 as iio

    render = _animation(tmp_path / f"reach{suffix}", suffix)
    before = _digest(render)
    _small_frames(monkeypatch)
    argv = [str(a) for a in ["simulate", "--model", base / "model.json", base / "trials.npz", "--trial", "0"]]
    argv += ["--render", str(render)]
    real = iio.imwrite

    def cut_short(path, *args, **kwargs):
        Path(path).write_bytes(b"GIF89a half a file")
        raise KeyboardInterrupt

    monkeypatch.setattr(iio, "imwrite", cut_short)
    assert main(argv) == 130
    assert _digest(render) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [render.name]  # no temporary left
    monkeypatch.setattr(iio, "imwrite", real)
    assert main(argv) == 0
    assert _digest(render) != before and f"wrote {render} (3 frames)" in capsys.readouterr().out
    assert len(iio.imread(render, index=None, **({"plugin": "FFMPEG"} if suffix == ".mp4" else {}))) == 3


def test_evaluate_checks_every_output_before_writing_any(base, tmp_path, capsys):
    (tmp_path / "afile").write_text("x")
    _fails(
        [
            "evaluate",
            "--model",
            base / "model.json",
            base / "trials.npz",
            "--out",
            tmp_path / "ev.json",
            "--predictions",
            tmp_path / "afile" / "p",
        ],
        capsys,
        r"--predictions: .*afile is a file, not a folder",
    )
    assert not (tmp_path / "ev.json").exists()


def test_evaluate_predictions_never_overwrite_an_input(base, tmp_path, capsys):
    pred = tmp_path / "pred"
    pred.mkdir()
    trials = load_trials(base / "trials.npz")
    model = pred / "S01_P2_right_S01_P2_T01.csv"  # the name the first trial's prediction would get
    shutil.copy(base / "model.json", model)
    before = _digest(model)
    _fails(
        ["evaluate", "--model", model, base / "trials.npz", "--out", tmp_path / "ev.json", "--predictions", pred],
        capsys,
        r"--predictions .* is the input file",
    )
    assert _digest(model) == before and not (tmp_path / "ev.json").exists()
    assert trials[0].id == "S01/P2/right/S01_P2_T01"


@pytest.mark.parametrize("command", ["evaluate", "preprocess"])
def test_an_export_never_replaces_the_users_own_files(base, tmp_path, capsys, command):
    """An export replaces only an earlier export's files: an index.csv of the user's own, or a file its name would
    take that the earlier export's index does not list, is refused and left as it was."""
    folder = tmp_path / "EX"
    folder.mkdir()
    trials, recording = base / "trials.npz", sorted((base / "syn").glob("*.trc"))[0]
    argv = {
        "evaluate": ["evaluate", "--model", base / "model.json", trials, "--out", tmp_path / "o.json"],
        "preprocess": ["preprocess", recording, "--markers", MARKERS, "--out", tmp_path / "o.npz"],
    }[command]
    option = {"evaluate": "--predictions", "preprocess": "--export"}[command]
    mine = folder / "index.csv"
    mine.write_text("subject,note\nS01,my own table\n")
    _fails(
        [*argv, option, folder],
        capsys,
        rf"index\.csv: {option}: exists and is not the index of an earlier export \(its header is neither "
        r"id,file,set,converged nor an earlier export's id,file,set\)",
    )
    assert mine.read_text() == "subject,note\nS01,my own table\n" and not (tmp_path / argv[-1]).exists()
    mine.unlink()
    assert main([*map(str, argv), option, str(folder)]) == 0  # an export, then a file of the user's own beside it
    name = next(p for p in sorted(folder.glob("*.csv")) if p.name != "index.csv").name
    (folder / name).unlink()
    (folder / "index.csv").write_text("id,file,set\n")  # an earlier export that did not write that name
    (folder / name).write_text("my own file\n")
    capsys.readouterr()
    _fails([*argv, option, folder], capsys, rf"{name}: {option}: exists and is not a file of the earlier export")
    assert (folder / name).read_text() == "my own file\n"


def test_an_export_never_removes_the_files_it_reads(base, tmp_path, capsys):
    """`preprocess EX/*.mot --export EX` removed its own inputs: the earlier export's index listed them and this
    export, whose names differ, removes what the earlier one wrote and it does not."""
    ex = tmp_path / "EX"
    assert (
        main(
            [
                "preprocess",
                str(base / "syn"),
                "--markers",
                MARKERS,
                "--out",
                str(tmp_path / "a.npz"),
                "--export",
                str(ex),
            ]
        )
        == 0
    )
    inputs = sorted(ex.glob("*.mot"))
    before = {p: _digest(p) for p in ex.iterdir()}
    capsys.readouterr()
    _fails(
        ["preprocess", *inputs, "--subject", "S01", "--out", tmp_path / "b.npz", "--export", ex],
        capsys,
        rf"{re.escape(str(inputs[0]))}: --export: is an input file, which an earlier export in .* listed and this one "
        r"would remove",
    )
    assert {p: _digest(p) for p in ex.iterdir()} == before and not (tmp_path / "b.npz").exists()


def test_reproduce_and_sensitivity_refuse_their_input_folder_as_output(base, tmp_path, capsys):
    syn = tmp_path / "syn"
    shutil.copytree(base / "syn", syn)
    _fails(
        ["reproduce", "--quick", "--data", syn, "--out", syn, "--workers", "1"], capsys, r"--out is the input folder"
    )
    run = tmp_path / "run"
    run.mkdir()
    _fails(["sensitivity", run, "--out", run], capsys, r"--out is the input folder")


# ---------------------------------------------------------------------- 2. an interrupt is an interrupt
def _swallowing_solver():
    """What CasADi does when Ctrl-C arrives mid-solve: the KeyboardInterrupt raised by the signal handler is
    caught, and a failed solve is returned."""
    try:
        signal.raise_signal(signal.SIGINT)  # to this thread: delivered before it returns
        for _ in range(1000):  # the handler runs between bytecodes
            pass
    except KeyboardInterrupt:
        return "failed solve"
    return "solved"


@pytest.fixture
def ctrl_c():
    """Python's own Ctrl-C handler for the test: a job started in the background inherits SIGINT ignored, and
    the guard rightly leaves an ignored signal alone."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_an_interrupt_swallowed_by_a_solver_is_raised_when_it_returns(ctrl_c):
    with pytest.raises(KeyboardInterrupt):
        with solver_interrupts():
            _swallowing_solver()


def test_sigterm_swallowed_by_a_solver_is_raised_as_terminated():
    def on_term(signum, frame):
        raise Terminated()

    old = signal.signal(signal.SIGTERM, on_term)
    try:
        with pytest.raises(Terminated):
            with solver_interrupts():
                try:
                    signal.raise_signal(signal.SIGTERM)
                    for _ in range(1000):
                        pass
                except KeyboardInterrupt:
                    pass  # swallowed
    finally:
        signal.signal(signal.SIGTERM, old)
    assert signal.getsignal(signal.SIGTERM) is old


def test_a_command_ended_outright_in_compiled_code_leaves_no_temporary(base, tmp_path):
    """A SIGINT swallowed while ``evaluate`` writes its output (as a video encoder or a solver can: here the
    temporary's sync never returns): the command is ended outright after the grace period, and the temporary of
    the write in progress is removed first; ``simulate --render`` left its animation's before."""
    from children import interrupted_while_syncing

    out, marker = tmp_path / "metrics.json", tmp_path / "syncing"
    argv = ["evaluate", "--model", base / "model.json", base / "trials.npz", "--out", out]
    rc, err = interrupted_while_syncing(argv, "path.name.startswith('.metrics.json.')", marker, tmp_path)
    assert rc == 130, err
    assert sorted(f.name for f in tmp_path.iterdir()) == ["syncing"]


def test_a_recording_guard_never_raises_inside_the_solver(ctrl_c):
    """Crocoddyl's guard only records: nothing is raised inside (boost::python would abort), the solver's own
    callback sees the signal pending, and it is raised once the solve returns."""
    from reachirl.errors import interrupt_pending

    seen = []
    with pytest.raises(KeyboardInterrupt):
        with solver_interrupts(stop_solver=False):
            signal.raise_signal(signal.SIGINT)  # to this thread: delivered before it returns
            for _ in range(1000):
                pass
            seen.append(interrupt_pending())
    assert seen == [True]
    assert not interrupt_pending()


@pytest.mark.parametrize(
    "command, other",
    [("evaluate", "model"), ("fit", "metrics"), ("simulate", "model"), ("fit", "user"), ("evaluate", "sim")],
)
def test_out_never_replaces_a_json_of_another_kind(base, tmp_path, capsys, command, other):
    """A JSON --out that exists must be the command's own earlier output: a model, another command's JSON or a
    file of the user's own, given by mistake, is refused and left as it was."""
    metrics, sim = tmp_path / "metrics.json", tmp_path / "sim.json"
    assert main(["evaluate", "--model", str(base / "model.json"), str(base / "trials.npz"), "--out", str(metrics)]) == 0
    existing = {
        "model": tmp_path / "model.json",
        "metrics": metrics,
        "sim": sim,
        "user": tmp_path / "notes.json",
    }[other]
    if other == "model":
        shutil.copy(base / "model.json", existing)
    elif other == "sim":
        existing.write_text('{"backend": "casadi", "mode": "pd", "substeps": 10, "trials": []}')
    elif other == "user":
        existing.write_text('{"my": "own notes"}')
    before = _digest(existing)
    capsys.readouterr()
    model, trials = base / "model.json", base / "trials.npz"
    argv = {
        "evaluate": ["evaluate", "--model", model, trials, "--out", existing],
        "fit": ["fit", trials, "--sections", "1", "--nodes", "20", "--out", existing],
        "simulate": ["simulate", "--model", model, trials, "--trial", "0", "--out", existing],
    }[command]
    kind = {"evaluate": "METRICS", "fit": "MODEL", "simulate": "SIM"}[command]
    _fails(argv, capsys, rf"{existing.name}: --out: exists and is not a {kind}\.json \(an earlier output")
    assert _digest(existing) == before


@pytest.mark.parametrize("other", ["numpy", "damaged"])
def test_preprocess_out_never_replaces_an_npz_that_is_not_a_trials_file(base, tmp_path, capsys, other):
    """An NPZ --out that exists must be preprocess's own earlier trials file: another program's NPZ (or one that
    cannot be read as a trials file), given by mistake, is refused and left as it was; a trials file is replaced."""
    existing = tmp_path / "data.npz"
    if other == "numpy":
        np.savez(existing, recording=np.arange(5.0))
    else:
        existing.write_bytes((base / "trials.npz").read_bytes()[:500])
    before = _digest(existing)
    recording = sorted((base / "syn").glob("*.trc"))[0]
    argv = ["preprocess", recording, "--markers", MARKERS, "--out", existing]
    _fails(argv, capsys, r"data\.npz: --out: exists and is not a reachirl trials file \(an earlier output")
    assert _digest(existing) == before
    own = tmp_path / "own.npz"
    save_trials(own, load_trials(base / "trials.npz")[:2])
    assert main(["preprocess", str(recording), "--markers", MARKERS, "--out", str(own)]) == 0
    assert len(load_trials(own)) == 1


def _npz_with_header(path: Path, header: dict) -> Path:
    np.savez(path, **{"meta.json": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), "0/t": np.arange(5.0)})
    return path


@pytest.mark.parametrize("fmt", ["reachirl-trials-cache/1", "reachirl-trials/1.5", "other-tool/1", 1])
def test_preprocess_out_refuses_an_npz_whose_header_is_not_a_trials_files(base, tmp_path, capsys, fmt):
    existing = _npz_with_header(tmp_path / "data.npz", {"format": fmt, "trials": []})
    before = _digest(existing)
    recording = sorted((base / "syn").glob("*.trc"))[0]
    argv = ["preprocess", recording, "--markers", MARKERS, "--out", existing]
    _fails(argv, capsys, r"data\.npz: --out: exists and is not a reachirl trials file \(an earlier output")
    assert _digest(existing) == before


def test_preprocess_out_replaces_a_trials_file_of_another_format_version(base, tmp_path, capsys, monkeypatch):
    """A trials file that an older (or newer) reachirl wrote is preprocess's own output too: it is replaced, not
    refused as if it were another program's NPZ (it was, since only the current format's header was recognised)."""
    import reachirl.data.trial as trial_module

    older, trials = tmp_path / "older.npz", load_trials(base / "trials.npz")[:2]
    with monkeypatch.context() as m:  # what a reachirl of format version 0 wrote
        m.setattr(trial_module, "TRIALS_FORMAT", "reachirl-trials/0")
        save_trials(older, trials)
    with pytest.raises(InputError, match=r"unsupported format 'reachirl-trials/0', .*run `reachirl preprocess` again"):
        load_trials(older)
    recording = sorted((base / "syn").glob("*.trc"))[0]
    assert main(["preprocess", str(recording), "--markers", MARKERS, "--out", str(older)]) == 0
    assert len(load_trials(older)) == 1
    # and a reachirl of the next format version replaces a file of this one
    current = save_trials(tmp_path / "current.npz", trials)
    monkeypatch.setattr(trial_module, "TRIALS_FORMAT", "reachirl-trials/2")
    assert main(["preprocess", str(recording), "--markers", MARKERS, "--out", str(current)]) == 0
    capsys.readouterr()


@pytest.mark.parametrize("command", ["fit", "evaluate", "simulate"])
def test_out_replaces_the_commands_own_earlier_output(base, tmp_path, command):
    out = tmp_path / f"{command}.json"
    model, trials = str(base / "model.json"), str(base / "trials.npz")
    first, second = {
        "fit": (
            ["fit", trials, "--nodes", "20", "--max-iter", "1", "--sections", "1"],
            ["fit", trials, "--nodes", "20", "--max-iter", "1", "--sections", "2"],
        ),
        "evaluate": (["evaluate", "--model", model, trials], ["evaluate", "--model", model, trials]),
        "simulate": (["simulate", "--model", model, trials, "--trial", "0"], ["simulate", "--model", model, trials]),
    }[command]
    assert main([*first, "--out", str(out)]) == 0 and main([*second, "--out", str(out)]) == 0
    d = json.loads(out.read_text())
    n = {"fit": len(d.get("weights", [])), "evaluate": len(d.get("trials", [])), "simulate": len(d.get("trials", []))}
    assert n[command] == 2  # the second run's (fit: 2 sections; simulate: both trials)


@pytest.mark.parametrize("command", ["preprocess", "evaluate"])
def test_out_inside_the_export_folder_is_refused(base, tmp_path, capsys, command):
    """--out as the index.csv that --export (or --predictions) writes would leave the trials or metrics lost."""
    folder = tmp_path / "EX"
    folder.mkdir()
    (tmp_path / "EXL").symlink_to(folder)
    out = tmp_path / "EXL" / ".." / "EX" / ".." / "EXL" / "index.csv"  # the same file, through a link and ".."
    argv = {
        "preprocess": ["preprocess", base / "syn", "--markers", MARKERS, "--out", out, "--export", folder],
        "evaluate": [
            "evaluate",
            "--model",
            base / "model.json",
            base / "trials.npz",
            "--out",
            out,
            "--predictions",
            folder,
        ],
    }[command]
    option = "--export" if command == "preprocess" else "--predictions"
    _fails(argv, capsys, rf"--out is index\.csv, a file that {option} writes into .*EX; give each output its own path")
    assert not (folder / "index.csv").exists()


def test_a_path_through_a_link_and_dotdot_is_the_file_the_system_finds(tmp_path):
    """``L/../EX2/index.csv`` with ``L`` a link to ``deep/a`` is ``deep/EX2/index.csv``, not ``EX2/index.csv``."""
    (tmp_path / "deep" / "a").mkdir(parents=True)
    (tmp_path / "L").symlink_to(tmp_path / "deep" / "a")
    through = tmp_path / "L" / ".." / "EX2" / "index.csv"
    assert same_file(through, tmp_path / "deep" / "EX2" / "index.csv")
    assert not same_file(through, tmp_path / "EX2" / "index.csv")


# ---------------------------------------------------------------------- 3. only regular files are read
@pytest.mark.parametrize("command", ["preprocess", "fit", "evaluate", "simulate"])
def test_a_fifo_as_input_is_refused_at_once(base, tmp_path, capsys, command):
    fifo = tmp_path / ("in.trc" if command == "preprocess" else "in.npz")
    os.mkfifo(fifo)
    argv = {
        "preprocess": ["preprocess", fifo, "--markers", MARKERS, "--out", tmp_path / "p.npz"],
        "fit": ["fit", fifo, "--sections", "1", "--out", tmp_path / "m.json"],
        "evaluate": ["evaluate", "--model", base / "model.json", fifo, "--out", tmp_path / "e.json"],
        "simulate": ["simulate", "--model", base / "model.json", fifo],
    }[command]
    _fails(argv, capsys, r"in\.(trc|npz): is not a regular file \(a FIFO, device or socket\)")


def test_load_trials_refuses_a_fifo(tmp_path):
    os.mkfifo(tmp_path / "t.npz")
    with pytest.raises(InputError, match=r"t\.npz: is not a regular file"):
        load_trials(tmp_path / "t.npz")


# ---------------------------------------------------------------------- 4. recordings against their headers
def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_mot_cut_at_a_row_boundary_is_truncated(base, tmp_path, capsys):
    lines = _lines(base / "mot" / "S01_P2_T01.mot")
    assert "nRows=187" in lines
    cut = _write(tmp_path / "cut.mot", lines[:102])
    _fails(
        ["preprocess", cut, "--out", tmp_path / "p.npz"],
        capsys,
        r"cut\.mot: line 102: truncated file: the header says nRows=187, the file ends after 95 rows",
    )


def test_a_mot_claiming_absurd_rows_is_refused(base, tmp_path, capsys):
    lines = [("nRows=999999999" if ln.startswith("nRows=") else ln) for ln in _lines(base / "mot" / "S01_P2_T01.mot")]
    _fails(
        ["preprocess", _write(tmp_path / "big.mot", lines), "--out", tmp_path / "p.npz"],
        capsys,
        r"big\.mot: line 3: header field nRows=999999999 is not a row count in \[1, 10000000\]",
    )


def test_a_trc_cut_at_a_row_boundary_is_truncated(base, tmp_path, capsys):
    cut = _write(tmp_path / "cut.trc", _lines(base / "syn" / "S01_P2_T01.trc")[:100])
    _fails(
        ["preprocess", cut, "--markers", MARKERS, "--out", tmp_path / "p.npz"],
        capsys,
        r"cut\.trc: line 100: truncated file: the header says NumFrames=\d+, the file ends after 94 frames",
    )


def test_a_trc_missing_a_frame_or_with_another_rate_is_refused(base, tmp_path, capsys):
    lines = _lines(base / "syn" / "S01_P2_T01.trc")
    gap = _write(tmp_path / "gap.trc", lines[:49] + lines[50:])
    _fails(
        ["preprocess", gap, "--markers", MARKERS, "--out", tmp_path / "p.npz"],
        capsys,
        r"gap\.trc: line 50: frame number 45 where 44 was expected",
    )
    fields = lines[2].split("\t")
    fields[0] = "250.00"
    rate = _write(tmp_path / "rate.trc", [*lines[:2], "\t".join(fields), *lines[3:]])
    _fails(
        ["preprocess", rate, "--markers", MARKERS, "--out", tmp_path / "p.npz"],
        capsys,
        r"rate\.trc: line 3: the Time column steps 0\.01 s but the header's DataRate=250\.00 Hz means 0\.004 s",
    )


# ---------------------------------------------------------------------- 5. physical consistency at the door
def test_subject_info_lengths_far_from_the_markers_are_refused(base, tmp_path, capsys):
    si = tmp_path / "subjects.csv"
    rows = _lines(base / "syn" / "subjects.csv")
    head = rows[0].split(",")
    cells = rows[1].split(",")
    cells[head.index("upper_arm_m")], cells[head.index("forearm_m")] = "0.40", "0.55"
    _write(si, [rows[0], ",".join(cells)])
    _fails(
        [
            "preprocess",
            base / "syn" / "S01_P2_T01.trc",
            "--subject-info",
            si,
            "--subject",
            "S01",
            "--markers",
            MARKERS,
            "--out",
            tmp_path / "p.npz",
        ],
        capsys,
        r"subject S01: subject-info upper_arm_m = 0\.400 m but the markers measure 0\.\d+ m .* at most 20 % allowed",
    )


def _with_trials(base: Path, path: Path, **changes) -> Path:
    """The trials file with ``changes`` made to every trial, written past save_trials' checks (a file edited by
    hand, or by another tool)."""
    from dataclasses import replace
    from unittest import mock

    trials = [replace(t, **changes) for t in load_trials(base / "trials.npz")]
    with mock.patch("reachirl.data.trial._check_file_trials"):
        save_trials(path, trials)
    return path


@pytest.mark.parametrize("target", [-0.3, 0.0])
def test_a_target_behind_or_at_the_shoulder_is_exit_2(base, tmp_path, capsys, target):
    bad = _with_trials(base, tmp_path / "t.npz", target_x=target)
    for argv in (
        ["fit", bad, "--sections", "1", "--nodes", "20", "--out", tmp_path / "m.json"],
        ["evaluate", "--model", base / "model.json", bad, "--out", tmp_path / "e.json"],
    ):
        _fails(
            argv,
            capsys,
            r"t\.npz: trial 0 \(S01/P2/right/S01_P2_T01\): field 'target_x' = .* is outside the "
            r"arm's reach \(0, 0\.\d+\] m",
        )


def test_absurd_start_velocities_are_refused(base, tmp_path, capsys):
    tr = load_trials(base / "trials.npz")[0]
    bad = _with_trials(base, tmp_path / "t.npz", x0=np.r_[tr.x0[:2], 1e6, 0.0])
    _fails(
        ["evaluate", "--model", base / "model.json", bad, "--out", tmp_path / "e.json"],
        capsys,
        r"field 'x0': the start velocity q̇1 = 1e\+06 rad/s is outside \[-10, 10\] rad/s",
    )


@pytest.mark.parametrize("command", ["evaluate", "simulate"])
def test_a_model_rollout_outside_the_joint_limits_is_refused(base, tmp_path, capsys, command):
    m = json.loads((base / "model.json").read_text())
    m.setdefault("info", {})["rollout_q"] = [[1e6, 1.0]] + [[0.0, 1.0]] * 20
    (tmp_path / "m.json").write_text(json.dumps(m))
    argv = {
        "evaluate": ["evaluate", "--model", tmp_path / "m.json", base / "trials.npz", "--out", tmp_path / "e.json"],
        "simulate": ["simulate", "--model", tmp_path / "m.json", base / "trials.npz"],
    }[command]
    _fails(argv, capsys, r"m\.json: field 'info\.rollout_q', row 0: q1 = 1e\+06 rad is outside the joint limits")


def test_pd_gains_beyond_a_stable_step_are_refused(base, tmp_path, capsys):
    _fails(
        [
            "simulate",
            "--model",
            base / "model.json",
            base / "trials.npz",
            "--trial",
            "0",
            "--mode",
            "pd",
            "--kp",
            "100000",
            "--kd",
            "10000",
        ],
        capsys,
        r"--kd 10000 N·m·s/rad is outside \[0, [\d.]+\], the largest that MuJoCo's step of [\d.]+ ms integrates",
    )


@pytest.mark.parametrize("how", ["backwards", "upside down"])
def test_a_backwards_or_mirrored_recording_is_caught_in_preprocess(base, tmp_path, capsys, how):
    lines = _lines(base / "syn" / "S01_P2_T01.trc")
    head, rows = lines[:6], [r.split("\t") for r in lines[6:] if r.strip()]
    if how == "backwards":
        data = [r[2:] for r in rows][::-1]
        rows = [r[:2] + d for r, d in zip(rows, data, strict=True)]
    else:  # the vertical axis negated
        rows = [[*r[:2], *(str(-float(v)) if (j % 3 == 1 and v) else v for j, v in enumerate(r[2:]))] for r in rows]
    rec = _write(tmp_path / "rec.trc", head + ["\t".join(r) for r in rows])
    _fails(
        ["preprocess", rec, "--markers", MARKERS, "--out", tmp_path / "p.npz"],
        capsys,
        r"rec\.trc: the start posture q0 = .* lies outside the joint limits .*: a mirrored or backwards "
        r"recording\? \(a left arm needs --side left",
    )


# ---------------------------------------------------------------------- 6. checkpoints and no non-finite number
def test_an_edited_checkpoint_is_recomputed(tmp_path):
    from reachirl.experiments.results import load_unit, save_unit

    payload = {"result": {"key": "u", "fingerprint": "f", "weights": [[0.1, 0.2]], "rmse": 0.6317}, "arrays": {}}
    save_unit(tmp_path, payload)
    js = tmp_path / "units" / "u.json"
    assert load_unit(tmp_path, "u", "f")["rmse"] == 0.6317
    text = js.read_text()
    js.write_text(text.replace("0.6317", "1.1317"))
    assert load_unit(tmp_path, "u", "f") is None
    js.write_text(text.replace("0.1", "NaN"))
    assert load_unit(tmp_path, "u", "f") is None
    js.write_text(text)
    assert load_unit(tmp_path, "u", "f") is not None


def test_a_folder_in_a_checkpoint_s_place_is_named(tmp_path):
    from reachirl.experiments.results import load_unit

    (tmp_path / "units" / "u.json").mkdir(parents=True)
    with pytest.raises(InputError, match=r"units/u\.json: is not a regular file, where the unit's checkpoint goes"):
        load_unit(tmp_path, "u", "f")


def test_a_set_whose_docs_all_failed_says_so():
    from reachirl.experiments.no_data import annotate_no_data

    out = annotate_no_data(
        {"train": {"summary": {"n_trials": 3, "doc_failures": 3, "rmse_deg": {"q": {"mean": None, "std": None}}}}}
    )
    assert out["train"]["summary"]["rmse_deg"]["q"]["no_data"] == (
        "the DOC failed (did not converge) on all 3 trial(s) of this set; no RMSE"
    )


# ---------------------------------------------------------------------- 7. bad input is exit 2, not 1
def test_the_same_up_and_forward_axis_is_exit_2(base, tmp_path, capsys):
    _fails(
        [
            "preprocess",
            base / "syn" / "S01_P2_T01.trc",
            "--markers",
            MARKERS,
            "--out",
            tmp_path / "p.npz",
            "--plane",
            "axes",
            "--up-axis",
            "+y",
            "--forward-axis",
            "+y",
        ],
        capsys,
        r"--up-axis \+y and --forward-axis \+y are the same lab axis",
    )


# ---------------------------------------------------------------------- 8. errors name the file passed
def test_a_trial_error_names_the_trials_file_not_the_recording(base, tmp_path, capsys):
    with zipfile.ZipFile(base / "trials.npz") as z:
        entries = {n: z.read(n) for n in z.namelist()}
    buf = io.BytesIO()
    np.save(buf, np.load(io.BytesIO(entries["0/q.npy"])) * np.nan)
    entries["0/q.npy"] = buf.getvalue()
    bad = tmp_path / "q_nan.npz"
    with zipfile.ZipFile(bad, "w") as z:
        for n, b in entries.items():
            z.writestr(n, b)
    err = _fails(
        ["fit", bad, "--sections", "1", "--out", tmp_path / "m.json"],
        capsys,
        r"q_nan\.npz: trial 0 \(S01/P2/right/S01_P2_T01\): q contains NaN or infinite values$",
    )
    assert ".trc" not in err


# ---------------------------------------------------------------------- 9. minor
def test_a_missing_static_file_is_an_error(base, tmp_path, capsys):
    _fails(
        [
            "preprocess",
            base / "syn" / "S01_P2_T01.trc",
            "--markers",
            MARKERS,
            "--static",
            tmp_path / "nope.csv",
            "--out",
            tmp_path / "p.npz",
        ],
        capsys,
        r"nope\.csv: --static: file not found",
    )


def test_sensitivity_workers_are_bounded(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["sensitivity", str(tmp_path), "--out", str(tmp_path / "o"), "--workers", "10000"])
    assert e.value.code == 2
    assert "argument --workers: expected an integer in [1, 256], got 10000" in capsys.readouterr().err


def test_duplicate_npz_entries_and_manifest_rows_are_refused(base, tmp_path, capsys):
    dup = tmp_path / "dup.npz"
    shutil.copy(base / "trials.npz", dup)
    with zipfile.ZipFile(dup) as z:
        q = z.read("0/q.npy")
    with pytest.warns(UserWarning, match="Duplicate name"), zipfile.ZipFile(dup, "a") as z:
        z.writestr("0/q.npy", q)
    with pytest.raises(InputError, match=r"dup\.npz: entry 0/q\.npy appears twice in the archive"):
        load_trials(dup)
    syn = tmp_path / "syn"
    shutil.copytree(base / "syn", syn)
    rows = _lines(syn / "manifest.csv")
    _write(syn / "manifest.csv", [*rows, rows[1]])
    _fails(
        ["preprocess", "--manifest", syn / "manifest.csv", "--markers", MARKERS, "--out", tmp_path / "p.npz"],
        capsys,
        rf"manifest\.csv: line {len(rows) + 1}: file 'S01_P2_T01\.trc' is listed twice \(lines 2 and "
        rf"{len(rows) + 1}\)",
    )


def test_reproduce_subjects_are_bounded(capsys):
    with pytest.raises(SystemExit) as e:
        main(["reproduce", "--quick", "--subjects", "100000"])
    assert e.value.code == 2
    assert "argument --subjects: expected an integer in [2, 100], got 100000" in capsys.readouterr().err


def test_the_last_word_on_a_signal_is_never_muted(monkeypatch, capsys):
    """A solver guard mutes stderr once it caught a signal (what an abandoned solve prints is noise); one left open
    (e.g. in a suspended generator) once swallowed "terminated", leaving exit 143 without a word."""
    import argparse
    import signal
    import sys

    from reachirl import cli, errors

    monkeypatch.setattr(sys, "stderr", errors._MutedAfter(sys.stderr, [signal.SIGTERM]))
    print("noise", file=sys.stderr)
    assert cli._interrupted(argparse.Namespace(command="sensitivity"), terminated=True) == 143
    assert capsys.readouterr().err == "reachirl sensitivity: terminated\n"


@pytest.mark.parametrize("command", ["evaluate", "preprocess"])
def test_an_interrupted_export_leaves_no_earlier_index_or_main_output(base, tmp_path, capsys, monkeypatch, command):
    """Ctrl-C while the trajectories are exported: the earlier run's index.csv and main output (METRICS.json, the
    trials file) are gone, so nothing reads as finished over a mix of two runs' files; the rerun writes both."""
    import reachirl.data.exports as ex

    folder, out = tmp_path / "EX", tmp_path / ("m.json" if command == "evaluate" else "t.npz")
    argv = {
        "evaluate": ["evaluate", "--model", base / "model.json", base / "trials.npz", "--predictions", folder],
        "preprocess": ["preprocess", base / "syn" / "S01_P2_T01.trc", "--markers", MARKERS, "--export", folder],
    }[command] + ["--out", out]
    argv = [str(a) for a in argv]
    assert main(argv) == 0 and (folder / "index.csv").is_file() and out.is_file()
    real, calls = ex.atomic_write_text, []

    def interrupted(path, text, **kwargs):  # kwargs: durable=False of the trajectory files
        calls.append(path)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(path, text, **kwargs)

    monkeypatch.setattr(ex, "atomic_write_text", interrupted)
    capsys.readouterr()
    assert main(argv) == 130
    assert not (folder / "index.csv").exists() and not out.exists()
    monkeypatch.undo()
    assert main(argv) == 0 and (folder / "index.csv").is_file() and out.is_file()


def test_stdout_closed_by_its_reader_is_not_an_internal_error(tmp_path):
    """`reachirl preprocess ... | head -1`: the reader goes away; no traceback, no "internal error", not 0."""
    import subprocess
    import sys

    from reachirl.data.ue_adl import SAMPLE_DIR

    r, w = os.pipe()
    os.close(r)  # a reader that has already gone: the first write is a broken pipe
    exe = Path(sys.executable).parent / "reachirl"
    try:
        proc = subprocess.run(
            [str(exe), "preprocess", str(SAMPLE_DIR), "--markerset", "ue-adl", "--out", str(tmp_path / "t.npz")],
            stdout=w,
            stderr=subprocess.PIPE,
            text=True,
            timeout=300,
        )
    finally:
        os.close(w)
    assert proc.returncode == 141 and "rror" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert (tmp_path / "t.npz").is_file()  # written before the printout


def test_a_broken_pipe_that_is_not_stdout_is_an_internal_error(monkeypatch, capsys):
    from reachirl.cli import main, preprocess

    def broken(args):
        raise BrokenPipeError(32, "Broken pipe")  # e.g. a worker's pipe, while stdout is fine

    monkeypatch.setattr(preprocess, "run", broken)
    assert main(["preprocess", "x.c3d", "--out", "y.npz"]) == 1
    assert "internal error: BrokenPipeError" in capsys.readouterr().err


def test_sigterm_while_the_commands_load_is_said_and_exits_143():
    """The commands' modules load for a second or two before any work; a SIGTERM then ended the process with no
    word (killed by the signal) instead of exit 143 and "terminated", as Ctrl-C there gave 130."""
    import subprocess
    import sys

    script = (
        "import os, signal, sys, time\n"
        "import reachirl.cli as cli\n"
        "def loading(*commands):\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(10)\n"
        "cli.build_parser = loading\n"
        "sys.exit(cli.main(['fit', 'trials.npz']))\n"
    )
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert p.returncode == 143, p.stderr
    assert p.stderr == "reachirl: terminated\n"


@pytest.mark.parametrize(
    "argv",
    [
        ["fit", "t.npz", "--sections", "1"],
        ["evaluate", "--model", "m.json", "t.npz"],
        ["simulate", "--model", "m.json", "t.npz"],
        ["bench", "doc"],
        ["preprocess", "rec.trc"],
    ],
)
def test_an_output_file_given_as_a_folder_is_refused_not_written_under_its_name(tmp_path, capsys, argv):
    """`fit ... --out newm/` wrote a file named newm (a Path drops the slash)."""
    out = f"{tmp_path}/newm/"
    try:
        code = main([*argv, "--out", out])
    except SystemExit as e:  # argparse's refusal of the option
        code = e.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(r"--out: .*(a folder|ends with '/')", err[0]), err
    assert not (tmp_path / "newm").exists()


def test_a_refused_preprocess_of_a_folder_says_one_line_not_its_notes_first(base, tmp_path, capsys):
    """`preprocess FOLDER --subject-info EMPTY`: "note: using the folder's manifest ..." came before the refusal."""
    (tmp_path / "empty.csv").write_text("")
    _fails(
        ["preprocess", base / "syn", "--subject-info", tmp_path / "empty.csv", "--out", tmp_path / "o.npz"],
        capsys,
        r"empty\.csv: file is empty",
    )
    assert main(["preprocess", str(base / "syn"), "--out", str(tmp_path / "o.npz")]) == 0
    assert "note: using the folder's manifest" in capsys.readouterr().err  # said once the inputs pass
