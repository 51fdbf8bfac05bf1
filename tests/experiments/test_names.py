"""Postures and subjects sort with their numbers by value."""

from reachirl.experiments.names import natural_key


def test_numbers_sort_by_value():
    names = ["P10", "P2", "S03b", "P1", "ALL", "S03a", "S10", "S9"]
    assert sorted(names, key=natural_key) == ["ALL", "P1", "P2", "P10", "S03a", "S03b", "S9", "S10"]
