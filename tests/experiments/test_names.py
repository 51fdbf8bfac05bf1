"""Names: postures and subjects sort with their numbers by value, and a count of sections is written out."""

from reachirl.experiments.names import natural_key


def test_numbers_sort_by_value():
    names = ["P10", "P2", "S03b", "P1", "ALL", "S03a", "S10", "S9"]
    assert sorted(names, key=natural_key) == ["ALL", "P1", "P2", "P10", "S03a", "S03b", "S9", "S10"]


def test_table_headers_spell_out_sections():
    """The tables' columns read "· 8 sec.", which a reader takes for seconds: they are the weights' sections."""
    from reachirl.experiments.tables import ALL, ALL_TRIALS, SETS, seed_markdown, to_markdown

    empty = {p: {s: {} for s in SETS} for p in (ALL, ALL_TRIALS)}
    head = to_markdown(empty, [], [1, 8], {"train": "10", "cv": "10", "iscv": "20"}).splitlines()[0]
    assert "Training (10) · 1 section |" in head and "ISCV (20) · 8 sections |" in head, head
    assert "sec." not in seed_markdown()
