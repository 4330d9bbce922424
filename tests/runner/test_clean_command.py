"""`dynsplines clean`'s arguments: --pin takes comma-separated times, repeated; a bad one is one line."""
import pytest

from runner.cli import build_parser


def test_pins_are_comma_separated_and_may_be_repeated():
    args = build_parser().parse_args(["clean", "x.bvh", "--pin", "0.5,1.25", "--pin", "2", "--pin-ends"])
    assert [t for group in args.pin for t in group] == [0.5, 1.25, 2.0]
    assert args.pin_ends and args.func.__module__ == "runner.commands.clean"


def test_a_bad_pin_is_named(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["clean", "x.bvh", "--pin", "0.5,soon"])
    assert "'0.5,soon' is not a comma-separated list of times in seconds" in capsys.readouterr().err


def test_contacts_name_a_file_the_clean_takes():
    args = build_parser().parse_args(["clean", "x.bvh", "--contacts", "x.contacts.json"])
    assert str(args.contacts) == "x.contacts.json"
