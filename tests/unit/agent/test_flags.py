"""argparse types of the process entry points."""

import argparse

import pytest

from agent import flags as argtypes


def test_numbers_are_checked_with_the_bound_in_the_message():
    assert argtypes.positive("0.5") == 0.5
    assert argtypes.non_negative("0") == 0.0
    assert argtypes.probability("1") == 1.0
    for fn, bad, words in [(argtypes.positive, "0", "positive"),
                           (argtypes.positive, "inf", "positive"),
                           (argtypes.non_negative, "-1", ">= 0"),
                           (argtypes.non_negative, "nan", ">= 0"),
                           (argtypes.probability, "1.5", "[0, 1]")]:
        with pytest.raises(argparse.ArgumentTypeError, match=words.replace("[", r"\[")):
            fn(bad)


def test_run_id_is_the_protocol_rule():
    assert argtypes.run_id("demo-1") == "demo-1"
    with pytest.raises(argparse.ArgumentTypeError, match="run id"):
        argtypes.run_id("a/b")
