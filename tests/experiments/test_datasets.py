"""Where reproduce gets its trials: the built-in data set is preprocessed once, then read from the trials cache."""

import pytest

import reachirl.virtual
from reachirl.errors import InputError
from reachirl.experiments import datasets


def test_builtin_trials_are_preprocessed_once(tmp_path, monkeypatch):
    from recordings import synth

    folder = synth(tmp_path / "builtin", ("P4",), subjects=2, trials=1, seed=2)
    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(reachirl.virtual, "builtin_dataset_dir", lambda seed, n: folder)
    calls = []
    real = datasets.preprocess_folder

    def counting(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(datasets, "preprocess_folder", counting)
    first = datasets.load(None)
    second = datasets.load(None)
    assert len(calls) == 1 and second.describe() == first.describe() and second.truth == first.truth
    assert [t.source for t in second.trials] == [t.source for t in first.trials]
    assert second.describe()["fingerprint"] == datasets.fingerprint(real(folder))  # what preprocessing gives
    rows = (folder / "manifest.csv").read_text().splitlines()
    (folder / "manifest.csv").write_text("\n".join(rows[:-1]) + "\n")  # one recording fewer
    assert len(datasets.load(None).trials) == len(first.trials) - 1 and len(calls) == 2


def test_a_damaged_built_in_data_set_is_made_again(tmp_path, monkeypatch, caplog):
    """A recording of the cached built-in data cut short refused every later run ("line 31: truncated row"), without
    saying it was the cache's: the set is made again, once, with a warning."""
    from recordings import synth

    made = []

    def builtin(seed, n):
        folder = tmp_path / "builtin"
        if not (folder / "truth.json").is_file():
            made.append(synth(folder, ("P4",), subjects=2, trials=1, seed=2))
        return folder

    monkeypatch.setenv("REACHIRL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(reachirl.virtual, "builtin_dataset_dir", builtin)
    first = datasets.load(None)
    recording = sorted((tmp_path / "builtin").glob("*.trc"))[0]
    recording.write_text(recording.read_text()[:3000])
    again = datasets.load(None)
    assert len(made) == 2 and "is damaged" in caplog.text and recording.name in caplog.text
    assert again.describe()["fingerprint"] == first.describe()["fingerprint"]


def test_a_relative_data_path_is_recorded_absolute(tmp_path, monkeypatch):
    """results.json's ``source`` is what `reachirl sensitivity` reloads, from whatever folder it is run in."""
    from reachirl.data.trial import save_trials

    save_trials(tmp_path / "trials.npz", datasets.toy(n_subjects=1, postures=("P2",), n_trials=1, n_nodes=20).trials)
    monkeypatch.chdir(tmp_path)
    ds = datasets.load("trials.npz")
    assert ds.source == str(tmp_path.resolve() / "trials.npz")
    monkeypatch.chdir(tmp_path.parent)
    assert datasets.load(ds.source).describe()["fingerprint"] == ds.describe()["fingerprint"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"seed": "a"}, r"^seed must be an integer in \[0, 2\*\*32 - 1\], got 'a'$"),
        ({"seed": 1.5}, r"^seed must be an integer in \[0, 2\*\*32 - 1\], got 1\.5$"),
        ({"seed": True}, r"^seed must be an integer in \[0, 2\*\*32 - 1\], got True$"),
        ({"seed": -1}, r"^seed must be an integer in \[0, 2\*\*32 - 1\], got -1$"),
        ({"n_subjects": "3"}, r"^n_subjects must be an integer, got '3'$"),
    ],
)
def test_the_built_in_data_set_names_a_seed_or_subject_count_that_is_no_integer(kwargs, match):
    # a seed of "a" failed deep in the cache's key ("invalid literal for int() with base 10"), 1.5 and True were
    # read as seed 1: another population than the one asked for
    with pytest.raises(InputError, match=match):
        datasets.load(None, **kwargs)


def test_a_folders_manifest_given_as_data_asks_for_its_folder(tmp_path):
    """`--data FOLDER/manifest.csv` (the docs say "a folder with manifest.csv") read as "not a trials file"."""
    (tmp_path / "manifest.csv").write_text("file,subject,posture\nr.trc,S01,P2\n")
    with pytest.raises(InputError, match=r"manifest\.csv: a manifest, not a trials file: give the folder that holds"):
        datasets.load(tmp_path / "manifest.csv")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"seed": 3}, r"--data-seed 3 seeds the built-in virtual subjects; it cannot be combined with --data"),
        ({"marker_map": "shoulder=A,elbow=B,fingertip=D"}, r"t\.npz: --markers names the markers of a folder of"),
    ],
)
def test_options_of_the_built_in_data_or_of_recordings_are_refused_with_a_trials_file(tmp_path, kwargs, match):
    """`reproduce --data t.npz --data-seed 3` (or `--markers ...`) ran on the trials file, the option unused."""
    with pytest.raises(InputError, match=match):
        datasets.load(tmp_path / "t.npz", **kwargs)


def test_markers_for_a_folder_of_joint_angle_files_are_refused_as_unused(tmp_path, capsys):
    """A synth folder written as MOT (joint angles): --markers would be left unused, so it is refused naming the
    manifest; the folder without it loads (truth.json's own marker names do not count as the user's)."""
    from reachirl.cli import main
    from reachirl.virtual import SynthConfig, generate

    generate(tmp_path / "mot", SynthConfig(1, 1, postures=("P2",), fmt="mot", workers=1))
    markers = "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"
    with pytest.raises(InputError, match=r"manifest\.csv: --markers applies to marker recordings .* left unused"):
        datasets.load(tmp_path / "mot", marker_map=markers)
    assert len(datasets.load(tmp_path / "mot").trials) == 1
    argv = ["reproduce", "--data", str(tmp_path / "mot"), "--markers", markers, "--out", str(tmp_path / "run")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "manifest.csv: --markers applies to marker recordings" in err[0], err
    assert not (tmp_path / "run").exists()
