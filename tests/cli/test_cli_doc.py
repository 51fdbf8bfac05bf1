"""docs/cli.md is the parsers rendered: it cannot drift from ``reachirl <command> --help``."""

from pathlib import Path

from reachirl.cli import COMMANDS
from reachirl.cli.docs import render

DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"


def test_cli_doc_is_the_parsers_rendered():
    assert DOC.read_text(encoding="utf-8") == render(), (
        "docs/cli.md differs from the command-line parsers: regenerate it with `make docs` "
        "(or `python -m reachirl.cli.docs --out docs/cli.md`)"
    )


def test_every_command_and_option_is_rendered():
    text = render()
    for name in COMMANDS:
        assert f"\n## reachirl {name}\n" in text
    assert "| `--sections SECTIONS` |" in text  # fit's options, one row each
    assert "| `--markerset NAME\\|FILE` |" in text  # pipes escaped inside a table
    assert "`-h, --help`" not in text and "`-v, --verbose`" not in text  # said once, in the header
