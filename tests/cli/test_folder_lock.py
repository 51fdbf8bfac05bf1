"""Every command that writes into a folder holds it while it runs (reproduce and sensitivity are tested with
their runs): a second command into a held folder is refused, exit 2, in one line naming the folder, before it
changes anything."""

import errno
import subprocess
import sys

import pytest

from reachirl.cli import main
from reachirl.errors import InputError

HOLD = (  # another command holding the folder, as reachirl holds it
    "import fcntl, os, sys, time; fcntl.flock(os.open(sys.argv[1], os.O_RDONLY), fcntl.LOCK_EX); "
    "print(1, flush=True); time.sleep(120)"
)
TRY = (  # whether the folder is free: exit 0 when a lock could be taken now
    "import fcntl, os, sys; fcntl.flock(os.open(sys.argv[1], os.O_RDONLY), fcntl.LOCK_EX | fcntl.LOCK_NB)"
)


@pytest.fixture
def held(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "1"
        yield out
    finally:
        holder.kill()
        holder.wait()


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


def _free(folder) -> bool:
    return subprocess.run([sys.executable, "-c", TRY, str(folder)], capture_output=True).returncode == 0


def test_a_folder_is_held_from_the_start_or_once_made_and_released_at_the_end(tmp_path):
    from reachirl.io import holding_folder

    there = tmp_path / "there"
    there.mkdir()
    with holding_folder(there):
        assert not _free(there)  # held before any work
    assert _free(there)
    new = tmp_path / "new"
    with holding_folder(new) as make:
        assert not new.exists()  # a command that fails before its first write leaves no folder
        assert make() == new
        assert not _free(new)
        with holding_folder(new):  # a part of the command that holds it too (plot's drawing): no release at its end
            pass
        assert not _free(new)
    assert _free(new)


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
    reader = subprocess.Popen(
        [sys.executable, "-c", HOLD.replace("LOCK_EX", "LOCK_SH"), str(run)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert reader.stdout.readline().strip() == "1"
        with pytest.raises(
            InputError,
            match=r"^\S+/run: --out: another reachirl command is reading this folder now; wait for it to end, or "
            r"choose another --out$",
        ):
            hold_folder(run)
        with reading_folder(run):
            assert not _free(run)
        assert not _free(run)  # the other reader's
    finally:
        reader.kill()
        reader.wait()
    assert _free(run)
    with reading_folder(run):
        assert not _free(run)
    assert _free(run)


def test_a_file_system_without_locks_holds_nothing_and_the_command_goes_on(tmp_path, monkeypatch):
    import fcntl

    def no_locks(fd, op):
        raise OSError(errno.ENOLCK, "No locks available")

    from reachirl.io import holding_folder

    monkeypatch.setattr(fcntl, "flock", no_locks)
    with holding_folder(tmp_path / "out") as make:
        assert make().is_dir()
