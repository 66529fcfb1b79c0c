"""The configuration keys of the research toolkit: robot_id, participants, exclude_learned."""

from __future__ import annotations

from pathlib import Path

import pytest

from kasparctl.config import ConfigError, default_robot_id, parse_config

PILOT = '[game]\nvariant = "pilot"\nlocations = ["box", "shelf", "basket"]\n'


@pytest.mark.parametrize(
    ("text", "variant_excludes"),
    [
        ("", {"names": True, "pilot": False}),
        ('exclude_learned = "names"\n', {"names": True, "pilot": False}),
        ('exclude_learned = "always"\n', {"names": True, "pilot": True}),
        ('exclude_learned = "never"\n', {"names": False, "pilot": False}),
    ],
)
def test_exclude_learned_by_variant(text: str, variant_excludes: dict[str, bool]) -> None:
    names = parse_config("[game]\n" + text, "k.toml")
    pilot = parse_config(PILOT + text, "k.toml")
    assert names.game.exclude_learned is variant_excludes["names"]
    assert pilot.game.exclude_learned is variant_excludes["pilot"]


def test_a_bad_exclude_learned_names_the_choices() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config('[game]\nexclude_learned = "sometimes"\n', "k.toml")
    assert str(caught.value) == (
        "k.toml: game.exclude_learned: expected one of 'names', 'always', 'never', "
        "found 'sometimes'"
    )


def test_the_robot_id_is_configured_or_derived_from_the_hashed_machine_id(tmp_path: Path) -> None:
    assert parse_config('robot_id = "kaspar-3"\n', "k.toml").robot() == "kaspar-3"
    machine_id = tmp_path / "machine-id"
    machine_id.write_text("0123456789abcdef0123456789abcdef\n")
    derived = default_robot_id((machine_id,))
    assert derived.startswith("robot-") and len(derived) == len("robot-") + 12
    assert "0123456789abcdef" not in derived  # hashed, never the machine id itself
    assert default_robot_id((machine_id,)) == derived  # stable
    other = tmp_path / "other"
    other.write_text("fedcba9876543210fedcba9876543210\n")
    assert default_robot_id((other,)) != derived
    # Without any machine id the host name stands in, still a valid code.
    assert default_robot_id((tmp_path / "missing",)).startswith("robot-")
    assert parse_config("", "k.toml").robot() == default_robot_id()


@pytest.mark.parametrize("robot_id", ["=cmd()", "-1", "", "a b", "x" * 33])
def test_a_robot_id_must_be_a_safe_code(robot_id: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(f'robot_id = "{robot_id}"\n', "k.toml")
    assert caught.value.key == "robot_id"
    assert "expected a code: 1 to 32 letters, digits" in caught.value.message


def test_participant_codes_set_the_group_size() -> None:
    config = parse_config('[[sessions]]\ngroup = "G1"\nparticipants = ["P07", "P12"]\n', "k.toml")
    (plan,) = config.sessions
    assert plan.participants == ("P07", "P12")
    assert config.group_size(plan) == 2


@pytest.mark.parametrize(
    ("entry", "key", "message"),
    [
        (
            'participants = ["P07", "P07"]',
            "sessions[0].participants",
            "expected distinct names, found 'P07' more than once",
        ),
        (
            'participants = ["=HYPERLINK(1)"]',
            "sessions[0].participants[0]",
            "expected a code: 1 to 32 letters, digits, '-' or '_', first a letter or digit, "
            "found '=HYPERLINK(1)'",
        ),
        (
            'children = ["Amira", "Ben"]\nparticipants = ["P07"]',
            "sessions[0].participants",
            "expected 2 codes (one per name in children), found 1",
        ),
        (
            'group_size = 3\nparticipants = ["P07", "P12"]',
            "sessions[0].participants",
            "expected 3 codes (one per child of group_size), found 2",
        ),
        (
            'participants = ["A", "B", "C", "D", "E", "F", "G", "H", "I", "J", "K"]',
            "sessions[0].participants",
            "expected at most 6 codes, found 11",
        ),
    ],
)
def test_bad_participant_codes_are_named(entry: str, key: str, message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(f'[[sessions]]\ngroup = "G1"\n{entry}\n', "k.toml")
    assert (caught.value.key, caught.value.message) == (key, message)
