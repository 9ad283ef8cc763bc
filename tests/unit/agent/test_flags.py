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


def test_robot_ids_take_lists_and_ranges():
    assert argtypes.robot_ids("2,3") == (2, 3)
    assert argtypes.robot_ids("8-11,20") == (8, 9, 10, 11, 20)
    for bad in ("", "a", "3,3", "2-1", "-1", "1-2,2"):
        with pytest.raises(argparse.ArgumentTypeError, match="robot ids"):
            argtypes.robot_ids(bad)


def test_a_relay_is_a_router_name_and_its_robots():
    assert argtypes.relay("b=2,3") == ("b", (2, 3))
    assert argtypes.relay("host-2=4-5") == ("host-2", (4, 5))
    for bad in ("b", "B=1", "=1", "b/c=1", "b=x"):
        with pytest.raises(argparse.ArgumentTypeError):
            argtypes.relay(bad)


def test_a_zid_is_lowercase_hex_without_leading_zero():
    assert argtypes.zid("e1f0a5") == "e1f0a5"
    for bad in ("", "0e1", "E1F0", "xyz", "1" * 33):
        with pytest.raises(argparse.ArgumentTypeError, match="Zenoh id"):
            argtypes.zid(bad)
