"""Phrases: the shipped books and their limits in every language, picking (fixed or varied),
and every load error by its text. The uncertainty levels are tests/test_scripts.py's."""

from __future__ import annotations

import copy
import functools
import itertools
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from kasparctl.game.phrases import (
    MAX_SENTENCE_WORDS,
    REQUIRED_LINES,
    STEP4_SENTENCES,
    PhraseBook,
    PhraseError,
    PhrasePicker,
    limit_problems,
    load_phrasebook,
    parse_phrasebook,
    pick_index,
    sentences,
    word_count,
)
from kasparctl.game.scripts import ALL_LEVELS, LAST_ONE, LINE_PREFIX, SURE_LEFT

SAMPLE_VALUES = {
    "bag": "3",
    "bags": "6",
    "toy": "giraffe",
    "location": "red box",
    "where": "in the red box",
    "child": "Sam",
    "mover": "Sam",
    "presser": "Ali",
    "number": "2",
    "robot": "Robin",
}
SHIPPED = sorted(
    path.stem for path in (Path(__file__).resolve().parents[1] / "phrases").glob("*.toml")
)
# The longest each placeholder plausibly is, per language: a two-word first name,
# the longest toy and location phrase of the examples. A language the table lacks is
# checked with the English values (names and toys are the configuration's anyway).
LONGEST = {
    "en": {
        "bag": "6", "bags": "6", "toy": "crocodile", "location": "bookshelf",
        "where": "on the top shelf", "child": "Anna Maria", "mover": "Anna Maria",
        "presser": "Anna Maria", "number": "6", "robot": "Kaspar",
    },
}  # fmt: skip
# Lines of step 4, said again and again: at most two sentences (the brief's limit).
STEP4_KEYS = [
    key
    for key in REQUIRED_LINES
    if key.split(".")[0] in ("guess", "react", "uncertainty", "turn", "prompt", "listen")
]


@functools.cache
def shipped() -> PhraseBook:
    # Cached rather than a fixture: hypothesis refuses function-scoped fixtures.
    return load_phrasebook("en")


def values_for(book: PhraseBook, key: str) -> dict[str, str]:
    return {name: SAMPLE_VALUES[name] for name in book.placeholders[key]}


# A small, valid phrase file built from REQUIRED_LINES, so the error tests keep
# working when a line is added; each test breaks exactly one thing.


def valid_document() -> dict[str, Any]:
    document: dict[str, Any] = {}
    for key, spec in REQUIRED_LINES.items():
        table, name = key.split(".")
        slots = " ".join(f"{{{placeholder}}}" for placeholder in sorted(spec.placeholders))
        document.setdefault(table, {})[name] = [f"{key} one {slots}", f"{key} two {slots}"]
    return document


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(value)


def to_toml(table: dict[str, Any], prefix: str = "") -> str:
    def is_table_array(value: Any) -> bool:
        return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)

    plain = {k: v for k, v in table.items() if not isinstance(v, dict) and not is_table_array(v)}
    out = [f"{k} = {toml_value(v)}" for k, v in plain.items()]
    for key, value in table.items():
        path = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            out += [f"[{path}]", to_toml(value, path)]
    for key, value in table.items():
        path = f"{prefix}.{key}" if prefix else key
        if is_table_array(value):
            for item in value:
                out += [f"[[{path}]]", to_toml(item, path)]
    return "\n".join(out) + "\n"


def parse(document: dict[str, Any]) -> PhraseBook:
    return parse_phrasebook(to_toml(document), "fixture.toml")


def error_of(document: dict[str, Any]) -> str:
    with pytest.raises(PhraseError) as caught:
        parse(document)
    assert str(caught.value) == (
        f"{caught.value.source}: {caught.value.key}: {caught.value.message}"
    )
    assert caught.value.source == "fixture.toml"
    return str(caught.value)


def broken(change: Any) -> dict[str, Any]:
    document = copy.deepcopy(valid_document())
    change(document)
    return document


# The shipped books -------------------------------------------------------------


def test_shipped_english_loads_with_every_key():
    book = shipped()
    assert book.language == "en"
    assert book.source.endswith("en.toml")
    assert set(book.keys) == set(REQUIRED_LINES)
    for level in ALL_LEVELS:
        assert book.variants(LINE_PREFIX + level), level


def test_shipped_english_has_enough_variety_for_the_varied_script():
    book = shipped()
    for key, spec in REQUIRED_LINES.items():
        assert len(book.variants(key)) >= spec.variety, key


def test_every_shipped_line_fills_in_completely():
    book = shipped()
    for key in book.keys:
        for index in range(len(book.variants(key))):
            text = book.render(key, index, **values_for(book, key))
            assert "{" not in text and "}" not in text, (key, text)
            assert text.strip() == text and text, (key, text)


@pytest.mark.parametrize("language", SHIPPED)
def test_every_line_of_every_book_keeps_the_limits(language):
    """Every sentence at most 12 words, every line at most its sentences (two in step 4),
    filled with the longest plausible values: in every shipped language."""
    book = load_phrasebook(language)
    assert limit_problems(book, LONGEST.get(language, LONGEST["en"])) == []
    for key in STEP4_KEYS:
        assert REQUIRED_LINES[key].max_sentences <= STEP4_SENTENCES, key


def test_the_limits_catch_a_long_sentence_and_a_long_line():
    document = valid_document()
    document["react"]["wrong"] = [
        "Oh no, that one was not the {toy} that I was thinking of just now.",
        "No. Not the {toy}. Sorry.",
    ]
    problems = limit_problems(parse(document), LONGEST["en"])
    assert problems == [
        f"react.wrong[0]: expected at most {MAX_SENTENCE_WORDS} words in a sentence, found 15: "
        "'Oh no, that one was not the crocodile that I was thinking of just now.'",
        "react.wrong[1]: expected at most 2 sentences, found 3: "
        "['No.', 'Not the crocodile.', 'Sorry.']",
    ]


@pytest.mark.parametrize(
    ("language", "text", "expected"),
    [
        ("en", "Hello. I am Kaspar. You are my teachers today.", [1, 3, 5]),
        ("en", "Hooray! I know the lion.", [1, 4]),
        ("fr", "C'est le lion ? Appuie sur le bouton vert !", [3, 5]),
        ("fr", "Bonjour ! Je m'appelle Kaspar.", [1, 3]),
        ("de", "Ist das der Löwe? Drück den grünen Knopf.", [4, 4]),
        ("de", "Das sind 1.5 Bit. Gut!", [4, 1]),
        ("nl", "Is het de leeuw? Druk op de groene knop.", [4, 5]),
        ("nl", "Dank je wel. Tot ziens!", [3, 2]),
        ("it", "È il leone? Premi il pulsante verde.", [3, 4]),
        ("it", "Grazie! Ciao a tutti.", [1, 3]),
    ],
)
def test_sentences_and_words_in_each_language(language, text, expected):
    assert [word_count(said) for said in sentences(text, language)] == expected


def test_the_paper_scripts_lines_are_the_first_wordings():
    """The paper's three levels, one fixed line each: the first wording of each key."""
    book = shipped()
    picker = PhrasePicker(book, np.random.default_rng(0), fixed=True)
    for level in ("no_idea", "idea_not_sure", "sure"):
        key = LINE_PREFIX + level
        said = {picker.line(key) for _ in range(20)}
        assert said == {book.variants(key)[0]}, key
    assert [picker.line("guess.names", child="Sam", toy="lion") for _ in range(3)] == [
        "Sam, is it the lion?"
    ] * 3


def test_no_idioms_in_the_shipped_english():
    """The idioms the old book had, and their like, are gone for good."""
    book = shipped()
    text = " ".join(v.lower() for key in book.keys for v in book.variants(key))
    for idiom in ("silly me", "muddled", "nap", "is anybody there", "woohoo", "ouch"):
        assert idiom not in text, idiom


def test_the_varied_script_says_why_it_is_sure():
    book = shipped()
    assert book.variants(LAST_ONE)[0] == "Only one name is left."
    assert book.variants(SURE_LEFT)[0] == "The other names were wrong."


def test_sentences_start_with_a_capital_after_a_placeholder():
    book = shipped()
    assert (
        book.render("teach.roles", 0, mover="child 1", presser="child 2")
        == "Child 1, please move my arm. Child 2, please press green."
    )
    assert book.fill("names.child", number="2") == "child 2"


# Picking ---------------------------------------------------------------------


def test_picker_never_repeats_a_variant_immediately():
    book = shipped()
    picker = PhrasePicker(book, np.random.default_rng(7))
    for key in book.keys:
        said = [picker.line(key, **values_for(book, key)) for _ in range(200)]
        if len(book.variants(key)) > 1:
            assert all(a != b for a, b in itertools.pairwise(said)), key
        # And it still uses every variant, rather than alternating between two.
        expected = {
            book.render(key, i, **values_for(book, key)) for i in range(len(book.variants(key)))
        }
        assert set(said) == expected, key


def test_a_fixed_picker_draws_nothing():
    rng = np.random.default_rng(3)
    before = rng.bit_generator.state
    picker = PhrasePicker(shipped(), rng, fixed=True)
    assert len({picker.line("react.wrong", toy="lion") for _ in range(10)}) == 1
    assert rng.bit_generator.state == before


def test_a_single_variant_is_said_every_time():
    document = broken(lambda d: d["react"].update(all_learned=["Yay!"]))
    picker = PhrasePicker(parse(document), np.random.default_rng(0))
    assert [picker.line("react.all_learned") for _ in range(5)] == ["Yay!"] * 5


def test_picks_are_reproducible_from_the_seed():
    book = shipped()
    first = PhrasePicker(book, np.random.default_rng(42))
    second = PhrasePicker(book, np.random.default_rng(42))
    assert [first.line("react.wrong", toy="lion") for _ in range(30)] == [
        second.line("react.wrong", toy="lion") for _ in range(30)
    ]


def test_pick_index_is_uniform_over_the_others():
    rng = np.random.default_rng(0)
    counts = np.bincount([pick_index(4, rng, avoid=2) for _ in range(4000)], minlength=4)
    assert counts[2] == 0
    assert all(1200 < count < 1470 for count in counts[[0, 1, 3]])


def test_placeholders_are_filled():
    book = shipped()
    rng = np.random.default_rng(0)
    assert "giraffe" in book.line("guess.names", rng, child="Sam", toy="giraffe")
    pilot = book.line("guess.pilot", rng, child="Sam", toy="lion", where="on the shelf")
    assert "lion" in pilot and "on the shelf" in pilot
    assert "Sam" in book.line("turn.first", rng, child="Sam")
    assert "bag 4" in book.line("teach.bag", rng, bag="4")
    assert "{" not in book.line("react.learned", rng, toy="zebra")


def test_literal_braces_survive():
    document = broken(lambda d: d["react"].update(all_learned=["Yay {{!}}"]))
    assert parse(document).line("react.all_learned", np.random.default_rng(0)) == "Yay {!}"


# Asking wrongly --------------------------------------------------------------


def test_asking_for_an_unknown_key_is_named():
    book = shipped()
    with pytest.raises(PhraseError) as caught:
        book.line("react.wrog", np.random.default_rng(0))
    assert str(caught.value).endswith(
        "en.toml: react.wrog: unknown key; did you mean 'react.wrong'?"
    )
    assert caught.value.key == "react.wrog"


def test_a_missing_value_is_named():
    picker = PhrasePicker(shipped(), np.random.default_rng(0))
    with pytest.raises(PhraseError) as caught:
        picker.line("guess.pilot", child="Sam", toy="lion")
    assert str(caught.value).endswith(
        "en.toml: guess.pilot: expected values for {child}, {toy}, {where}, found {child}, "
        "{toy} (missing {where})"
    )


def test_an_extra_value_is_named():
    with pytest.raises(PhraseError) as caught:
        shipped().line("react.all_learned", np.random.default_rng(0), toy="lion")
    assert str(caught.value).endswith(
        "en.toml: react.all_learned: expected values for none, found {toy} (not allowed {toy})"
    )


def test_a_value_that_is_not_text_is_named():
    with pytest.raises(PhraseError) as caught:
        shipped().line("teach.bag", np.random.default_rng(0), bag=3)  # type: ignore[arg-type]
    assert str(caught.value).endswith("en.toml: teach.bag: expected text for {bag}, found int")


def test_a_bad_call_leaves_the_picker_untouched():
    book = shipped()
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    picker = PhrasePicker(book, rng_a)
    with pytest.raises(PhraseError):
        picker.line("guess.names", child="Sam")
    assert rng_a.integers(1000) == rng_b.integers(1000)


# Every load error, by its text -----------------------------------------------


def test_missing_key():
    document = broken(lambda d: d["react"].pop("wrong"))
    assert error_of(document) == "fixture.toml: react.wrong: required key is missing"


def test_missing_table():
    document = broken(lambda d: d.pop("confirm"))
    assert error_of(document) == "fixture.toml: confirm.next_step: required key is missing"


def test_missing_uncertainty_level():
    document = broken(lambda d: d["uncertainty"].pop("idea_not_sure"))
    assert error_of(document) == (
        "fixture.toml: uncertainty.idea_not_sure: required key is missing"
    )


def test_the_old_bands_table_is_refused_with_where_the_levels_went():
    document = broken(
        lambda d: d["uncertainty"].update(
            bands=[{"name": "sure", "min": 0.0, "max": math.inf, "lines": ["Sure."]}]
        )
    )
    message = error_of(document)
    assert message.startswith(
        "fixture.toml: uncertainty.bands: the uncertainty levels and their limits are no "
        "longer in the phrase book (they are the study's: kasparctl/game/scripts.py)"
    )
    assert "uncertainty.no_idea" in message and "uncertainty.idea_not_sure" in message


def test_empty_line_list():
    document = broken(lambda d: d["react"].update(all_learned=[]))
    assert error_of(document) == (
        "fixture.toml: react.all_learned: expected at least one line, found an empty array"
    )


def test_empty_line():
    document = broken(lambda d: d["react"].update(all_learned=["Yay", "  "]))
    assert error_of(document) == (
        "fixture.toml: react.all_learned[1]: expected a line to say, found an empty string"
    )


def test_repeated_variant():
    document = broken(lambda d: d["react"].update(all_learned=["Yay", "Hooray", "Yay"]))
    assert error_of(document) == (
        "fixture.toml: react.all_learned[2]: expected a different variant, "
        "found a repeat of react.all_learned[0]"
    )


def test_unknown_key_with_suggestion():
    document = broken(lambda d: d["react"].update(wrog=["No"]))
    assert error_of(document) == "fixture.toml: react.wrog: unknown key; did you mean 'react.wrong'?"


def test_unknown_table():
    document = broken(lambda d: d.update(snacks={"crisps": ["Yum"]}))
    assert error_of(document) == "fixture.toml: snacks: unknown key"


def test_unknown_placeholder():
    document = broken(
        lambda d: d["guess"].update(names=["{child}, is this the {toy}?", "Is it {tey}?"])
    )
    assert error_of(document) == (
        "fixture.toml: guess.names[1]: expected placeholders from {child}, {the_toy}, {toy}, "
        "found {tey}"
    )


def test_placeholder_where_none_is_allowed():
    document = broken(lambda d: d["react"].update(all_learned=["Yay {child}!"]))
    assert error_of(document) == (
        "fixture.toml: react.all_learned[0]: expected placeholders from none, found {child}"
    )


def test_positional_placeholder():
    document = broken(lambda d: d["guess"].update(names=["Is this the {}?"]))
    assert error_of(document) == (
        "fixture.toml: guess.names[0]: expected placeholders from {child}, {the_toy}, {toy}, "
        "found {}"
    )


def test_malformed_format_string():
    document = broken(lambda d: d["guess"].update(names=["Is this the {toy?"]))
    assert error_of(document) == (
        "fixture.toml: guess.names[0]: expected {name} placeholders or {{ }} for braces, "
        "found a malformed one (expected '}' before end of string)"
    )


def test_format_spec_is_refused():
    document = broken(lambda d: d["guess"].update(names=["Is this the {toy!r}?"]))
    assert error_of(document) == (
        "fixture.toml: guess.names[0]: expected a plain {toy}, found a conversion or format spec in it"
    )


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (
            lambda d: d["react"].update(all_learned="Yay"),
            "react.all_learned: expected an array of text, found a string ('Yay')",
        ),
        (
            lambda d: d["react"].update(all_learned=["Yay", 3]),
            "react.all_learned[1]: expected text, found an integer (3)",
        ),
        (
            lambda d: d.update(react=["Yay"]),
            "react: expected a table, found an array",
        ),
        (
            lambda d: d.update(uncertainty=True),
            "uncertainty: expected a table, found a boolean (True)",
        ),
    ],
)
def test_wrong_types(change, expected):
    assert error_of(broken(change)) == f"fixture.toml: {expected}"


def test_syntax_error():
    text = to_toml(valid_document()) + "\n[react\nwrong = 'x'\n"
    with pytest.raises(PhraseError) as caught:
        parse_phrasebook(text, "fixture.toml")
    assert re.fullmatch(
        r"fixture\.toml: \(syntax\): not valid TOML: .*\(at line \d+, column \d+\)",
        str(caught.value),
    )
    assert caught.value.key == "(syntax)"


def test_not_utf8(tmp_path):
    (tmp_path / "en.toml").write_bytes(b"\xff\xfe")
    with pytest.raises(PhraseError) as caught:
        load_phrasebook("en", str(tmp_path))
    assert str(caught.value).startswith(f"{tmp_path / 'en.toml'}: (file): expected UTF-8 text")


# Languages and overrides -----------------------------------------------------


def test_missing_override_file(tmp_path):
    with pytest.raises(PhraseError) as caught:
        load_phrasebook("fr", str(tmp_path))
    assert (
        str(caught.value)
        == f"{tmp_path / 'fr.toml'}: (file): cannot read it: No such file or directory"
    )
    assert caught.value.source == str(tmp_path / "fr.toml")


def test_override_error_names_the_override_file(tmp_path):
    (tmp_path / "en.toml").write_text(to_toml(broken(lambda d: d["react"].pop("wrong"))))
    with pytest.raises(PhraseError) as caught:
        load_phrasebook("en", str(tmp_path))
    assert str(caught.value) == f"{tmp_path / 'en.toml'}: react.wrong: required key is missing"


def test_a_second_language_in_an_override_directory(tmp_path):
    document = valid_document()
    document["guess"]["names"] = [
        "{child}, est-ce le {toy} ?",
        "{child}, c'est le {toy} ?",
        "Est-ce le {toy}, {child} ?",
    ]
    document["react"]["all_learned"] = ["Youpi !", "Bravo !", "Merci !"]
    (tmp_path / "fr.toml").write_text(to_toml(document), encoding="utf-8")
    book = load_phrasebook("fr", str(tmp_path))
    assert book.language == "fr"
    assert book.source == str(tmp_path / "fr.toml")
    rng = np.random.default_rng(0)
    assert book.line("guess.names", rng, child="Léa", toy="lion") in {
        "Léa, est-ce le lion ?",
        "Léa, c'est le lion ?",
        "Est-ce le lion, Léa ?",
    }
    assert sentences("Léa, est-ce le lion ? Oui !", "fr") == ["Léa, est-ce le lion ?", "Oui !"]


def test_an_override_directory_replaces_the_shipped_english(tmp_path):
    (tmp_path / "en.toml").write_text(to_toml(valid_document()))
    book = load_phrasebook("en", str(tmp_path))
    assert book.source == str(tmp_path / "en.toml")
    assert book.variants("react.all_learned") == (
        "react.all_learned one ",
        "react.all_learned two ",
    )


def test_unknown_shipped_language():
    with pytest.raises(PhraseError) as caught:
        load_phrasebook("xx")
    assert caught.value.key == "(file)"
    assert caught.value.source.endswith("xx.toml")
    assert "expected one of the shipped languages (" in str(caught.value)
    assert "en" in caught.value.message and "found 'xx'" in caught.value.message


def test_language_code_cannot_leave_the_directory(tmp_path):
    with pytest.raises(PhraseError) as caught:
        load_phrasebook("../en", str(tmp_path))
    assert str(caught.value) == (
        f"{tmp_path}: language: expected a language code such as 'en', found '../en'"
    )


def test_phrasebook_is_immutable():
    book = shipped()
    with pytest.raises(AttributeError):
        book.source = "elsewhere"  # type: ignore[misc]
    with pytest.raises(TypeError):
        book.lines["react.wrong"] = ("x",)  # type: ignore[index]
