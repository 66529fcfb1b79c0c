"""Fuzzing the inputs kasparctl reads from disk: configuration, phrases, records, state.

Each loader must either accept its input or fail with its own exception type and a
message that names the file and the key; a records file must never crash a resume
and must never lose a byte.
"""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from kasparctl.config import Config, ConfigError, parse_config
from kasparctl.game.jsonl import TORN_SUFFIX, read_json_lines
from kasparctl.game.phrases import PhraseBook, PhraseError, parse_phrasebook
from kasparctl.game.session import state_from_plain, state_to_plain
from kasparctl.game.state import GameState, StateError

REPO = Path(__file__).resolve().parents[1]
EXAMPLE_CONFIG = (REPO / "systemd" / "kaspar.toml").read_text(encoding="utf-8")
EN_PHRASES = (REPO / "phrases" / "en.toml").read_text(encoding="utf-8")
SOURCE = "kaspar.toml"

# Examples per property: bounded so the file runs in seconds; raise it for a deeper
# run, e.g. KASPAR_FUZZ_EXAMPLES=5000 pytest tests/test_fuzz_inputs.py.
EXAMPLES = int(os.environ.get("KASPAR_FUZZ_EXAMPLES", "150"))
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

# A key path as ConfigError writes it: "game.toys", "sessions[1].group",
# "learner.profiles.quick.alpha", or one of the markers.
_KEY = re.compile(r"kaspar\.toml: (\(syntax\)|\(file\)|\(top level\)|[\w\-\[\].]+): \S")

# -- mutations of a TOML text --------------------------------------------------------

# Values of every TOML type, to put where another type belongs.
TOML_VALUES = st.sampled_from(
    [
        '"text"',
        '""',
        "0",
        "-1",
        "1.5",
        "1e400",
        "nan",
        "inf",
        "true",
        "[]",
        "[1, 2]",
        '["a", "a"]',
        "{}",
        "{ x = 1 }",
        "1979-05-27T07:32:00Z",
        "07:32:00",
        '"\\u0000"',
        "99999999999999999999",
    ]
)
KEY_NAMES = st.from_regex(r"[a-z_]{1,12}", fullmatch=True)


@st.composite
def mutated_toml(draw: st.DrawFn, text: str) -> str:
    lines = text.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        if not lines:
            break
        index = draw(st.integers(0, len(lines) - 1))
        operation = draw(
            st.sampled_from(["delete", "duplicate", "garble", "retype", "unknown", "swap"])
        )
        line = lines[index]
        if operation == "delete":
            del lines[index]
        elif operation == "duplicate":
            lines.insert(index, line)
        elif operation == "garble":
            position = draw(st.integers(0, len(line)))
            junk = draw(st.text(max_size=6))
            cut = draw(st.integers(0, 3))
            lines[index] = line[:position] + junk + line[position + cut :]
        elif operation == "retype":
            if "=" in line and not line.lstrip().startswith("#"):
                key = line.split("=", 1)[0]
                lines[index] = f"{key}= {draw(TOML_VALUES)}"
        elif operation == "unknown":
            lines.insert(index + 1, f"{draw(KEY_NAMES)} = {draw(TOML_VALUES)}")
        else:
            other = draw(st.integers(0, len(lines) - 1))
            lines[index], lines[other] = lines[other], lines[index]
    return "\n".join(lines) + "\n"


def _assert_config_error(error: ConfigError) -> None:
    message = str(error)
    assert message.startswith(f"{SOURCE}: "), message
    assert _KEY.match(message), message
    assert error.key and error.message


def _check_config(text: str) -> None:
    try:
        config = parse_config(text, SOURCE)
    except ConfigError as error:
        _assert_config_error(error)
    else:
        assert isinstance(config, Config)


def test_the_example_configuration_is_valid() -> None:
    assert isinstance(parse_config(EXAMPLE_CONFIG, SOURCE), Config)


@FUZZ
@given(st.text(max_size=300))
@example("[game]\ntoys = 1\n")
@example("sessions = 3\n")
@example("[[sessions]]\n")
def test_config_random_text(text: str) -> None:
    _check_config(text)


@FUZZ
@given(mutated_toml(EXAMPLE_CONFIG))
def test_config_mutations_of_the_example(text: str) -> None:
    _check_config(text)


@FUZZ
@given(st.binary(max_size=200))
def test_config_random_bytes(data: bytes) -> None:
    try:
        config = parse_config(data, SOURCE)
    except ConfigError as error:
        _assert_config_error(error)
    else:
        assert isinstance(config, Config)


# -- phrases -------------------------------------------------------------------------


def _check_phrases(data: str | bytes, source: str) -> None:
    try:
        book = parse_phrasebook(data, source, language="en")
    except PhraseError as error:
        assert str(error).startswith(f"{source}: "), str(error)
        assert error.key
    else:
        assert isinstance(book, PhraseBook)


def test_the_shipped_phrases_are_valid() -> None:
    assert isinstance(parse_phrasebook(EN_PHRASES, "en.toml"), PhraseBook)


@FUZZ
@given(mutated_toml(EN_PHRASES))
@example(EN_PHRASES.replace("Hello! My name", "Hello {child!r} My name", 1))
@example(EN_PHRASES.replace("Hello! My name", "Hello {0} My name", 1))
@example(EN_PHRASES.replace("Hello! My name", "Hello {} My name", 1))
@example(EN_PHRASES.replace("Hello! My name", "Hello {child.x} My name", 1))
@example(EN_PHRASES.replace("Hello! My name", "Hello {child[0]} My name", 1))
def test_phrases_mutations(text: str) -> None:
    _check_phrases(text, "phrases/en.toml")


@FUZZ
@given(st.binary(max_size=200) | st.text(max_size=200))
def test_phrases_random_input(data: bytes | str) -> None:
    _check_phrases(data, "phrases/xx.toml")


# -- records -------------------------------------------------------------------------

JSON_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(-(2**53), 2**53)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=12)
)
JSON_VALUES = st.recursive(
    JSON_SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)
RECORDS = st.dictionaries(st.text(max_size=8), JSON_VALUES, max_size=5)
# Lines that are not a JSON object: never a newline inside (a line is a line).
GARBAGE_LINES = (
    st.binary(max_size=30).filter(lambda b: b"\n" not in b)
    | st.sampled_from([b"", b"[]", b"1", b'"x"', b"null", b"{", b'{"a": 1', b"\xff\xfe", b"{}}"])
).filter(lambda b: not _is_object(b))


def _is_object(line: bytes) -> bool:
    try:
        return isinstance(json.loads(line), dict)
    except ValueError:
        return False


def _encode(record: dict[str, Any]) -> bytes:
    return json.dumps(record, ensure_ascii=False).encode("utf-8")


def _check_read(path: Path, data: bytes, repair: bool) -> tuple[list[dict[str, Any]], list[str]]:
    path.write_bytes(data)
    torn = path.with_name(path.name + TORN_SUFFIX)
    torn.unlink(missing_ok=True)
    result = read_json_lines(path, repair=repair)
    assert all(isinstance(record, dict) for record in result.records)
    assert all(isinstance(warning, str) and str(path) in warning for warning in result.warnings)
    after = path.read_bytes()
    if repair:
        assert after == b"" or after.endswith(b"\n"), after
        moved = torn.read_bytes() if torn.exists() else b""
        # Nothing lost: what stayed, then what was moved aside, is the original
        # (the .torn copy may add one newline to a tail that had none).
        assert data.startswith(after)
        rest = data[len(after) :]
        assert moved in (rest, rest + b"\n"), (data, after, moved)
    else:
        assert after == data
        assert not torn.exists()
    return result.records, result.warnings


@FUZZ
@given(data=st.binary(max_size=300), repair=st.booleans())
@example(data=b"\n", repair=True)
@example(data=b"{}\n\n", repair=True)
@example(data=b'{"a":1}\n[]', repair=True)
def test_records_random_bytes(data: bytes, repair: bool) -> None:
    with tempfile.TemporaryDirectory() as directory:
        _check_read(Path(directory) / "records.jsonl", data, repair)


@st.composite
def damaged_log(draw: st.DrawFn) -> tuple[list[bytes], list[int], bytes]:
    """Lines (each a record or garbage), the indices of the good ones, and a torn tail."""
    records = draw(st.lists(RECORDS, max_size=8))
    lines = [_encode(record) for record in records]
    good = list(range(len(lines)))
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, len(lines)))
        lines.insert(at, draw(GARBAGE_LINES))
        good = [i + 1 if i >= at else i for i in good]
    # A torn tail: a prefix of a record's encoding, no newline (a power cut mid-write).
    whole = _encode(draw(RECORDS))
    tail = whole[: draw(st.integers(0, len(whole) - 1))]
    return lines, good, tail


@FUZZ
@given(log=damaged_log(), repair=st.booleans())
def test_records_with_garbage_and_a_torn_tail(
    log: tuple[list[bytes], list[int], bytes], repair: bool
) -> None:
    lines, good, tail = log
    data = b"".join(line + b"\n" for line in lines) + tail
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "records.jsonl"
        records, warnings = _check_read(path, data, repair)
        # Every good line, in order; nothing else.
        assert records == [json.loads(lines[i]) for i in good]
        bad = [number for number in range(1, len(lines) + 1) if number - 1 not in good]
        last_is_bad = bool(lines) and (len(lines) - 1) not in good
        for number in bad:
            if number == len(lines) and last_is_bad and not tail:
                # A bad last line is taken for the torn tail.
                assert any("torn" in warning for warning in warnings), warnings
            else:
                assert any(f"line {number}:" in warning for warning in warnings), (number, warnings)
        if tail:
            assert any("torn" in warning for warning in warnings), warnings
        if repair:
            # Read again: the same records. (A bad line that the cut made the last
            # one is taken for a torn tail in its turn: moved aside, not lost.)
            again = read_json_lines(path, repair=True)
            assert again.records == records


def test_records_missing_file_is_empty(tmp_path: Path) -> None:
    result = read_json_lines(tmp_path / "absent.jsonl", repair=True)
    assert result.records == [] and result.warnings == []


# -- game state ----------------------------------------------------------------------

STATE_KEYS = [
    "step",
    "learner",
    "progress",
    "offered",
    "trials",
    "turn",
    "target",
    "previous",
    "poses",
    "teach_round",
    "teach_bag",
    "undo",
    "paused",
]


def _valid_state() -> dict[str, Any]:
    from kasparctl.config import GameSettings
    from kasparctl.learning.learner import LearnerParams

    game = GameSettings()
    return state_to_plain(GameState.new(game, LearnerParams(), seed=1))


VALID_STATE = json.loads(json.dumps(_valid_state()))


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every place inside a plain value: dict keys and list indices, nested."""
    found = [prefix] if prefix else []
    if isinstance(value, dict):
        for key, inner in value.items():
            found += _paths(inner, (*prefix, key))
    elif isinstance(value, list):
        for index, inner in enumerate(value):
            found += _paths(inner, (*prefix, index))
    return found


STATE_PATHS = _paths(VALID_STATE)
# Values of the right kind but the wrong size or range, besides any JSON value.
ODD_VALUES = (
    JSON_VALUES
    | st.lists(JSON_SCALARS, max_size=2)
    | st.sampled_from([-1, 2**64, 2**200, -(2**70), 1e300, "", "PCG64", "MT19937", [], {}])
)


@st.composite
def state_dicts(draw: st.DrawFn) -> dict[str, Any]:
    """Random dicts, or the valid snapshot with values anywhere in it replaced or removed."""
    if draw(st.integers(0, 3)) == 0:
        return draw(st.dictionaries(st.sampled_from(STATE_KEYS) | st.text(max_size=6), JSON_VALUES))
    state = json.loads(json.dumps(VALID_STATE))
    for path in draw(st.lists(st.sampled_from(STATE_PATHS), min_size=1, max_size=3, unique=True)):
        parent: Any = state
        try:
            for step in path[:-1]:
                parent = parent[step]
            if draw(st.integers(0, 4)) == 0:
                del parent[path[-1]]
            else:
                parent[path[-1]] = draw(ODD_VALUES)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change removed or replaced this place
    return state


def test_the_valid_snapshot_restores() -> None:
    state = state_from_plain(json.loads(json.dumps(VALID_STATE)))
    assert state_to_plain(state)["step"] == "idle"


@settings(FUZZ, report_multiple_bugs=False)
@given(state_dicts())
def test_game_state_from_random_plain_data(data: dict[str, Any]) -> None:
    try:
        state = state_from_plain(data)
    except StateError:
        pass
    else:
        assert isinstance(state, GameState)
        assert not any(isinstance(x, float) and math.isnan(x) for x in state.offered)


# -- regressions: minimal examples of the defects the fuzzing found (now fixed) -------


def _state_with(**changes: Any) -> dict[str, Any]:
    state = json.loads(json.dumps(VALID_STATE))
    state.update(changes)
    return state


def _rng_state(**changes: Any) -> dict[str, Any]:
    learner = json.loads(json.dumps(VALID_STATE["learner"]))
    learner["rng"]["state"].update(changes)
    return learner


def test_regression_state_rng_integer_out_of_range_is_a_state_error() -> None:
    # numpy's PCG64.state setter raises OverflowError for a negative "inc".
    with pytest.raises(StateError):
        state_from_plain(_state_with(learner=_rng_state(inc=-1)))


def test_regression_state_poses_not_a_table_is_a_state_error() -> None:
    # data["poses"].items() on a list.
    with pytest.raises(StateError):
        state_from_plain(_state_with(poses=[]))


def test_regression_state_previous_too_short_is_a_state_error() -> None:
    # previous[1] on a one-element list.
    with pytest.raises(StateError):
        state_from_plain(_state_with(previous=[1]))


def test_regression_state_mt19937_key_too_short_is_a_state_error() -> None:
    # numpy's MT19937.state setter raises IndexError for a key shorter than 624 words.
    learner = json.loads(json.dumps(VALID_STATE["learner"]))
    learner["rng"] = {"bit_generator": "MT19937", "state": {"key": [1], "pos": 0}}
    with pytest.raises(StateError):
        state_from_plain(_state_with(learner=learner))


def test_regression_state_naming_another_numpy_callable_is_a_state_error() -> None:
    # getattr(np.random, name)() once ran whatever the snapshot named, e.g. "seed".
    learner = json.loads(json.dumps(VALID_STATE["learner"]))
    learner["rng"] = {"bit_generator": "seed", "state": {}}
    with pytest.raises(StateError, match="bit_generator: expected one of"):
        state_from_plain(_state_with(learner=learner))
