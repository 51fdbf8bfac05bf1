"""Figures drawn in worker processes: the same files as drawn here, the first error raised, nothing left running
or half written."""

import re

import numpy as np
import pytest

from children import children_gone
from reachirl.errors import InputError
from reachirl.experiments.rendering import FigureJob, drawing

FIGURES = "reachirl.experiments.figures"


def jobs(folder, pdf: bool = False):
    """Three small figures, two of them also as PDF with ``pdf``."""
    hist = {
        (p, n): [{"iteration": i, "merit": 1.0 / (i + 1 + n), "accepted": True} for i in range(4)]
        for p in ("P2", "P10")
        for n in (1, 3)
    }
    heads = {
        m: {s: {n: {"mean": 1.0 + k + n / 10, "std": 0.2} for n in (1, 3)} for s in ("train", "cv", "iscv")}
        for k, m in enumerate(("moirl", "kkt"))
    }
    rng = np.random.default_rng(0)
    shares = {p: rng.dirichlet(np.ones(7), size=3) for p in ("P1", "P2")}

    def paths(name):
        return ((folder / f"{name}.pdf",) if pdf else ()) + (folder / f"{name}.png",)

    return [
        FigureJob(f"{FIGURES}:plot_convergence", {"histories": hist, "sections": [1, 3]}, paths("convergence")),
        FigureJob(f"{FIGURES}:plot_methods", {"headlines": heads, "sections": [1, 3]}, paths("methods")),
        FigureJob(f"{FIGURES}:plot_truth", {"learned": shares, "true": shares, "title": "t"}, (folder / "truth.png",)),
    ]


def test_workers_draw_the_same_files_as_this_process(tmp_path):
    here, there = tmp_path / "here", tmp_path / "there"
    with drawing(jobs(here, pdf=True), workers=1) as d:
        assert not here.exists()  # drawn when waited for
    assert sorted(p.name for p in here.iterdir()) == [
        "convergence.pdf",
        "convergence.png",
        "methods.pdf",
        "methods.png",
        "truth.png",
    ]
    with drawing(jobs(there, pdf=True), workers=2) as d:
        written = d.wait()
    assert sorted(p.name for p in written) == sorted(p.name for p in here.iterdir())
    for p in here.iterdir():
        assert (there / p.name).read_bytes() == p.read_bytes(), p.name
    assert not [p for p in there.iterdir() if p.name.startswith(".")]  # no temporary file left
    assert children_gone()


def test_closing_after_the_figures_ends_the_pools_manager_thread(tmp_path):
    # concurrent.futures' exit hook writes to the manager thread's wake-up pipe without its lock; a thread still
    # closing that pipe at the command's exit made the write fail with an OSError traceback (Python 3.11)
    import concurrent.futures as cf

    with drawing(jobs(tmp_path), workers=2) as d:
        d.wait()
        manager = d._ended._manager
        assert manager is not None, "the pool ended by wait() is the one close() waits for"
    d.close()
    assert not manager.is_alive()
    wakeup = cf.process._threads_wakeups.get(manager)
    assert wakeup is None or wakeup._closed, "the exit hook skips a closed pipe"
    assert children_gone()


def test_a_figures_error_is_raised_and_the_workers_end(tmp_path):
    bad = [*jobs(tmp_path), FigureJob(f"{FIGURES}:no_such_plot", {}, (tmp_path / "bad.png",))]
    with pytest.raises(AttributeError, match="no_such_plot"), drawing(bad, workers=2):
        pass
    assert not (tmp_path / "bad.png").exists()
    assert children_gone()


def test_an_error_meanwhile_ends_the_workers_at_once(tmp_path):
    with pytest.raises(KeyboardInterrupt), drawing(jobs(tmp_path), workers=2):
        raise KeyboardInterrupt
    assert children_gone()
    for p in tmp_path.glob("*.png"):  # a figure is there whole or not at all (a temporary may be left)
        assert p.read_bytes().endswith(b"IEND\xaeB`\x82")


def test_workers_started_ahead_draw_the_same_files_and_end_with_their_block(tmp_path):
    from reachirl.experiments.rendering import FigureWorkers

    here, ahead_dir = tmp_path / "here", tmp_path / "ahead"
    with drawing(jobs(here), workers=1):
        pass
    with FigureWorkers(2) as ahead:
        ahead.start()
        pool = ahead.pool
        assert pool is not None and len(pool._processes) == 2  # started before any figure
        with drawing(jobs(ahead_dir), workers=2, ahead=ahead) as d:
            written = d.wait()
        assert ahead.pool is None  # taken over by the drawing, which ended it
    assert sorted(p.name for p in written) == sorted(p.name for p in here.iterdir())
    for p in here.iterdir():
        assert (ahead_dir / p.name).read_bytes() == p.read_bytes(), p.name
    assert children_gone()
    # started and never used (an error or a --max-units stop before the figures): ended with the block
    with pytest.raises(RuntimeError, match="stopped"), FigureWorkers(2) as ahead:
        ahead.start()
        raise RuntimeError("stopped")
    assert children_gone()
    with FigureWorkers(1) as one:  # one worker: figures are drawn in-process, nothing is started
        one.start()
        assert one.pool is None


def test_reachirls_figures_are_told_from_others(tmp_path):
    """What `plot` may replace: a PNG or PDF saved by figures.save carries reachirl's mark in its metadata; the same
    figure saved by matplotlib otherwise, another file under a figure's name or an empty one do not."""
    import shutil

    import matplotlib.pyplot as plt

    from reachirl.experiments.figures import is_marked_figure, save

    for ext in ("png", "pdf"):
        fig = plt.figure()
        plt.plot([0, 1], [1, 0])
        fig.savefig(tmp_path / f"theirs.{ext}", metadata={"Software" if ext == "png" else "Creator": "someone"})
        save(fig, tmp_path / f"ours.{ext}")
        assert is_marked_figure(tmp_path / f"ours.{ext}") and not is_marked_figure(tmp_path / f"theirs.{ext}")
    shutil.copy(tmp_path / "ours.pdf", tmp_path / "renamed.png")
    (tmp_path / "empty.png").write_bytes(b"")
    (tmp_path / "notes.pdf").write_text("reachirl\n")
    for name in ("renamed.png", "empty.png", "notes.pdf", "missing.png"):
        assert not is_marked_figure(tmp_path / name), name


def test_a_figures_mark_is_looked_for_in_its_first_64_kib_only(tmp_path, monkeypatch):
    """is_marked_figure reads at most _MARK_BYTES of a file: it read up to 64 chunks of 64 KiB each (4 MiB) of a
    PNG before its image data. A PNG whose mark stands behind 80 kB of other chunks (not one figures.save writes) is
    not taken as reachirl's, and no more than 64 KiB of it is read."""
    import builtins
    import io
    import struct
    import zlib

    from reachirl.experiments import figures
    from reachirl.experiments.figures import is_marked_figure

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0))
    mark = chunk(b"tEXt", b"Software\0" + figures.FIGURE_MARK.encode())
    tail = chunk(b"IDAT", zlib.compress(b"\0\0")) + chunk(b"IEND", b"")
    near, far = tmp_path / "near.png", tmp_path / "far.png"
    near.write_bytes(b"\x89PNG\r\n\x1a\n" + ihdr + mark + tail)
    far.write_bytes(b"\x89PNG\r\n\x1a\n" + ihdr + 2 * chunk(b"prIv", bytes(40_000)) + mark + tail)
    read, real_open = [], builtins.open

    class Counted(io.BufferedReader):
        def read(self, n=-1):
            data = super().read(n)
            read.append(len(data))
            return data

    monkeypatch.setattr(builtins, "open", lambda p, mode="r", *a, **k: Counted(real_open(p, "rb", buffering=0)))
    assert is_marked_figure(near)
    read.clear()
    assert not is_marked_figure(far)
    assert sum(read) <= figures._MARK_BYTES, sum(read)


def test_a_figure_worker_killed_is_said_as_such_and_the_others_end(tmp_path):
    import os
    import signal

    from reachirl.experiments.rendering import FigureWorkers

    with FigureWorkers(2) as ahead:
        ahead.start()
        victim = next(iter(ahead.pool._processes.values()))
        with pytest.raises(
            InputError,
            match=rf"^{re.escape(str(tmp_path))}: a worker process died \(killed, or out of memory\) while drawing "
            r"figure \w+\.png; the run's results are kept \(rerun to draw it again\)$",
        ):
            with drawing(jobs(tmp_path), workers=2, ahead=ahead):
                os.kill(victim.pid, signal.SIGKILL)
    assert children_gone()


def test_a_png_is_cropped_as_savefigs_tight_box_crops_it(tmp_path):
    """``save`` finds a PNG's tight box without matplotlib's layout-only draw: the same bytes as
    ``savefig(bbox_inches="tight")``, for a figure whose caption and legend lie outside the axes (and the
    figure); the figure keeps its own dpi."""
    import matplotlib.pyplot as plt

    from reachirl.experiments.figures import plot_weights, save

    shares = {(p, n): np.linspace(0.05, 0.9, n * 7).reshape(n, 7) for p in ("P1", "P2") for n in (1, 3)}
    fig = plot_weights(shares, ["P1", "P2"], [1, 3], note="a caption set below the axes, " * 12)
    fig.axes[0].legend(["shares"], loc="upper left", bbox_to_anchor=(1.02, 1.0))
    save(fig, tmp_path / "ours.png", close=False)
    fig.savefig(tmp_path / "tight.png", dpi=200, bbox_inches="tight", metadata={"Software": "reachirl"})
    assert (tmp_path / "ours.png").read_bytes() == (tmp_path / "tight.png").read_bytes()
    assert fig.dpi == 100.0, "the figure's own dpi is left as it was"
    plt.close(fig)
