"""Every command that writes into a folder holds it while it runs (reproduce and sensitivity are tested with
their runs): a second command into a held folder is refused, exit 2, in one line naming the folder, before it
changes anything."""

import errno

import pytest

from folder_locks import held_elsewhere, is_free
from reachirl.cli import main
from reachirl.errors import InputError


@pytest.fixture
def held(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    with held_elsewhere(out):
        yield out


# what each command would remove or replace first in the folder: an earlier output and a temporary being written
COMMANDS = {
    "synth": (["synth", "--out", "{out}", "--subjects", "1", "--trials", "1"], "--out", "truth.json"),
    "evaluate": (
        ["evaluate", "--model", "{tmp}/m.json", "{tmp}/t.npz", "--out", "{tmp}/metrics.json", "--predictions", "{out}"],
        "--predictions",
        "index.csv",
    ),
    "preprocess": (["preprocess", "{tmp}/a.trc", "--out", "{tmp}/t.npz", "--export", "{out}"], "--export", "index.csv"),
    "plot": (["plot", "--model", "{tmp}/m.json", "{tmp}/t.npz", "--out", "{out}"], "--out", "fig_prediction.png"),
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_command_into_a_folder_in_use_is_refused_before_it_changes_anything(command, held, capsys):
    argv, option, earlier = COMMANDS[command]
    (held / earlier).write_bytes(b"an earlier output")
    (held / f".{earlier}.abcd1234.tmp").write_bytes(b"being written by the command that holds the folder")
    before = {p.name: p.read_bytes() for p in held.iterdir()}
    argv = [a.format(out=held, tmp=held.parent) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"reachirl {command}: error: {held}: {option}: another reachirl command is writing into this folder now; "
        f"wait for it to end, or choose another {option}"
    ]
    assert {p.name: p.read_bytes() for p in held.iterdir()} == before


def test_a_folder_is_held_from_the_start_or_once_made_and_released_at_the_end(tmp_path):
    from reachirl.io import holding_folder

    there = tmp_path / "there"
    there.mkdir()
    with holding_folder(there):
        assert not is_free(there)  # held before any work
    assert is_free(there)
    new = tmp_path / "new"
    with holding_folder(new) as make:
        assert not new.exists()  # a command that fails before its first write leaves no folder
        assert make() == new
        assert not is_free(new)
        with holding_folder(new):  # a part of the command that holds it too (plot's drawing): no release at its end
            pass
        assert not is_free(new)
    assert is_free(new)


def test_a_folder_held_by_another_process_is_refused_naming_the_folder_and_option(held):
    from reachirl.io import holding_folder

    with pytest.raises(InputError, match=r"out: --export: another reachirl command is writing into this folder"):
        with holding_folder(held, "--export"):
            pass


def test_a_folder_being_read_refuses_a_writer_and_not_a_reader(tmp_path):
    # plot reads a run's folder under a shared lock: a reproduce into it is refused meanwhile, saying why
    from reachirl.io import hold_folder, reading_folder

    run = tmp_path / "run"
    run.mkdir()
    with held_elsewhere(run, shared=True):  # another command reading it
        with pytest.raises(
            InputError,
            match=r"^\S+/run: --out: another reachirl command is reading this folder now; wait for it to end, or "
            r"choose another --out$",
        ):
            hold_folder(run)
        with reading_folder(run):
            assert not is_free(run)
        assert not is_free(run)  # the other reader's
    assert is_free(run)
    with reading_folder(run):
        assert not is_free(run)
    assert is_free(run)


def test_a_file_system_without_locks_holds_nothing_and_the_command_goes_on(tmp_path, monkeypatch):
    import fcntl

    def no_locks(fd, op):
        raise OSError(errno.ENOLCK, "No locks available")

    from reachirl.io import holding_folder

    monkeypatch.setattr(fcntl, "flock", no_locks)
    with holding_folder(tmp_path / "out") as make:
        assert make().is_dir()


def test_a_folder_read_and_then_written_into_is_held_for_writing(tmp_path):
    # a shared lock kept while the process wrote into the folder let another command read it (or two such
    # processes write into it at once)
    import subprocess
    import sys

    from reachirl.io import hold_folder, reading_folder

    run = tmp_path / "run"
    run.mkdir()
    read = "import fcntl, os, sys; fcntl.flock(os.open(sys.argv[1], os.O_RDONLY), fcntl.LOCK_SH | fcntl.LOCK_NB)"
    with reading_folder(run):
        assert subprocess.run([sys.executable, "-c", read, str(run)]).returncode == 0  # readers share it
        hold_folder(run)
        assert subprocess.run([sys.executable, "-c", read, str(run)]).returncode != 0  # written: no other reader
    assert is_free(run)


def test_a_folder_read_here_and_elsewhere_is_refused_for_writing_and_stays_read(tmp_path):
    from reachirl.io import hold_folder, reading_folder

    run = tmp_path / "run"
    run.mkdir()
    with reading_folder(run):
        with held_elsewhere(run, shared=True):
            with pytest.raises(
                InputError, match=r"^\S+/run: --out: another reachirl command is reading this folder now; wait"
            ):
                hold_folder(run)
        assert not is_free(run)  # still read here (the system drops a shared lock it refuses to make exclusive)
    assert is_free(run)
