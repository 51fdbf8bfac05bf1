"""Virtual subjects recorded as real ones are, for the tests' fixtures: ``reachirl synth`` writes the
recordings, ``reachirl preprocess`` cuts them at a fingertip-speed threshold into a trials file."""

from pathlib import Path

from reachirl.cli import main

MARKERS = "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"


def synth(
    out: Path, postures: tuple[str, ...], subjects: int = 1, trials: int = 1, fmt: str = "trc", seed: int | None = None
) -> Path:
    """``reachirl synth`` into ``out`` (one worker); returns ``out``."""
    argv = [
        "synth",
        "--out",
        str(out),
        "--subjects",
        str(subjects),
        "--trials",
        str(trials),
        "--postures",
        *postures,
        "--format",
        fmt,
        "--workers",
        "1",
    ]
    assert main([*argv, *([] if seed is None else ["--seed", str(seed)])]) == 0
    return out


def preprocess(folder: Path, out: Path) -> Path:
    """``reachirl preprocess`` of a synth folder (its manifest and subject info) into the trials file ``out``."""
    assert (
        main(
            [
                "preprocess",
                "--manifest",
                str(folder / "manifest.csv"),
                "--subject-info",
                str(folder / "subjects.csv"),
                "--markers",
                MARKERS,
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out
