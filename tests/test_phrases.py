"""Phrases: the shipped English file, band lookup, variety, and every load error by its text."""

from __future__ import annotations

import copy
import functools
import itertools
import json
import math
import re
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kasparctl.game.phrases import (
    BAND_LINE_PREFIX,
    BAND_SPEC,
    NO_IDEA,
    NO_IDEA_TOLERANCE,
    REQUIRED_LINES,
    PhraseBook,
    PhraseError,
    PhrasePicker,
    load_phrasebook,
    parse_phrasebook,
    pick_index,
)

SAMPLE_VALUES = {
    "bag": "3",
    "toy": "giraffe",
    "location": "red box",
    "child": "child one",
    "joint": "left elbow",
}


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
    document["uncertainty"]["bands"] = [
        {"name": "sure", "min": 0.0, "max": 0.5, "lines": ["sure a", "sure b"]},
        {"name": "fairly_sure", "min": 0.5, "max": 1.0, "lines": ["fairly a", "fairly b"]},
        {"name": "idea_not_sure", "min": 1.0, "max": 2.0, "lines": ["idea a", "idea b"]},
        {"name": "unsure", "min": 2.0, "max": math.inf, "lines": ["unsure a", "unsure b"]},
    ]
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


# The shipped file ------------------------------------------------------------


def test_shipped_english_loads_with_every_key():
    book = shipped()
    assert book.language == "en"
    assert book.source.endswith("en.toml")
    for key in REQUIRED_LINES:
        assert book.variants(key), key


def test_shipped_english_has_enough_variety():
    book = shipped()
    for key, spec in REQUIRED_LINES.items():
        assert len(book.variants(key)) >= spec.variety, key
    for band in book.bands:
        assert len(book.variants(BAND_LINE_PREFIX + band.name)) >= BAND_SPEC.variety, band.name


def test_every_shipped_line_fills_in_completely():
    book = shipped()
    for key in book.keys:
        for index in range(len(book.variants(key))):
            text = book.render(key, index, **values_for(book, key))
            assert "{" not in text and "}" not in text, (key, text)
            assert text.strip() == text and text, (key, text)


def test_shipped_bands_follow_the_paper():
    book = shipped()
    assert [band.name for band in book.bands] == ["sure", "fairly_sure", "idea_not_sure", "unsure"]
    assert book.bands[0].min == 0.0
    assert book.bands[-1].max == math.inf
    sure = book.bands[0]
    assert sure.max <= 0.5  # paper: below 0.5 bits Kaspar is sure


@pytest.mark.parametrize(
    ("entropy", "n_candidates", "band"),
    [
        (2.585, 6, NO_IDEA),  # paper: log2(6) at the start of every problem
        (math.log2(6), 6, NO_IDEA),
        (1.58, 3, NO_IDEA),  # three names left, all equal: still no idea
        (math.log2(3), 3, NO_IDEA),
        (1.0, 2, NO_IDEA),
        (1.5, 6, "idea_not_sure"),  # paper: around 1.5 an idea but not sure
        (0.3, 6, "sure"),  # paper: below 0.5 sure
        (0.0, 6, "sure"),
        (0.0, 1, "sure"),  # one name left: nothing to be unsure about
        (0.5, 6, "fairly_sure"),
        (0.99, 6, "fairly_sure"),
        (1.0, 6, "idea_not_sure"),
        (2.0, 6, "unsure"),
        (2.4, 6, "unsure"),
        (1.5, 3, "idea_not_sure"),  # below log2(3) by more than the tolerance
    ],
)
def test_band_lookup(entropy, n_candidates, band):
    book = shipped()
    name, line = book.uncertainty(entropy, n_candidates, np.random.default_rng(1))
    assert name == band
    assert line in book.variants(BAND_LINE_PREFIX + band)
    assert book.band_for(entropy, n_candidates) == band


def test_uncertainty_rejects_impossible_entropies():
    book = shipped()
    with pytest.raises(PhraseError, match=r"en\.toml: uncertainty: expected an entropy <= log2"):
        book.band_for(2.7, 6)
    with pytest.raises(PhraseError, match=r"en\.toml: uncertainty: expected an entropy >= 0"):
        book.band_for(-0.5, 6)
    with pytest.raises(PhraseError, match=r"en\.toml: uncertainty: expected an entropy >= 0"):
        book.band_for(math.nan, 6)
    with pytest.raises(PhraseError, match=r"en\.toml: uncertainty: expected at least 1 candidate"):
        book.band_for(0.0, 0)


@settings(max_examples=500, deadline=None)
@given(data=st.data(), n_candidates=st.integers(min_value=1, max_value=12))
def test_every_entropy_has_a_band_containing_it(data, n_candidates):
    book = shipped()
    maximum = math.log2(n_candidates)
    entropy = data.draw(st.floats(min_value=0.0, max_value=maximum), label="entropy")
    seed = data.draw(st.integers(min_value=0, max_value=2**32 - 1), label="seed")
    name, line = book.uncertainty(entropy, n_candidates, np.random.default_rng(seed))
    assert line in book.variants(BAND_LINE_PREFIX + name)
    if name == NO_IDEA:
        assert n_candidates > 1
        assert entropy >= maximum - NO_IDEA_TOLERANCE
    else:
        band = next(band for band in book.bands if band.name == name)
        assert band.contains(entropy)


# Picking ---------------------------------------------------------------------


def test_picker_never_repeats_a_variant_immediately():
    book = shipped()
    picker = PhrasePicker(book, np.random.default_rng(7))
    for key in book.keys:
        said = [picker.line(key, **values_for(book, key)) for _ in range(200)]
        assert all(a != b for a, b in itertools.pairwise(said)), key
        # And it still uses every variant, rather than alternating between two.
        expected = {
            book.render(key, i, **values_for(book, key)) for i in range(len(book.variants(key)))
        }
        assert set(said) == expected, key


def test_picker_uncertainty_does_not_repeat_within_a_band():
    picker = PhrasePicker(shipped(), np.random.default_rng(3))
    said = [picker.uncertainty(2.585, 6)[1] for _ in range(100)]
    assert all(a != b for a, b in itertools.pairwise(said))


def test_a_single_variant_is_said_every_time():
    document = broken(lambda d: d["react"].update(happy=["Yay!"]))
    picker = PhrasePicker(parse(document), np.random.default_rng(0))
    assert [picker.line("react.happy") for _ in range(5)] == ["Yay!"] * 5


def test_picks_are_reproducible_from_the_seed():
    book = shipped()
    first = PhrasePicker(book, np.random.default_rng(42))
    second = PhrasePicker(book, np.random.default_rng(42))
    assert [first.line("react.sad") for _ in range(30)] == [
        second.line("react.sad") for _ in range(30)
    ]


def test_pick_index_is_uniform_over_the_others():
    rng = np.random.default_rng(0)
    counts = np.bincount([pick_index(4, rng, avoid=2) for _ in range(4000)], minlength=4)
    assert counts[2] == 0
    assert all(1200 < count < 1470 for count in counts[[0, 1, 3]])


def test_placeholders_are_filled():
    book = shipped()
    rng = np.random.default_rng(0)
    assert "giraffe" in book.line("guess.names", rng, toy="giraffe")
    pilot = book.line("guess.pilot", rng, toy="lion", location="red box")
    assert "lion" in pilot and "red box" in pilot
    assert "Sam" in book.line("turn.child", rng, child="Sam")
    assert "bag 4" in book.line("teach.move_arm", rng, bag="4")
    assert "left elbow" in book.line("fault.servo", rng, joint="left elbow")
    assert "{" not in book.line("react.learned", rng, toy="zebra")


def test_literal_braces_survive():
    document = broken(lambda d: d["react"].update(happy=["Yay {{!}}"]))
    assert parse(document).line("react.happy", np.random.default_rng(0)) == "Yay {!}"


# Asking wrongly --------------------------------------------------------------


def test_asking_for_an_unknown_key_is_named():
    book = shipped()
    with pytest.raises(PhraseError) as caught:
        book.line("react.hapy", np.random.default_rng(0))
    assert str(caught.value).endswith(
        "en.toml: react.hapy: unknown key; did you mean 'react.happy'?"
    )
    assert caught.value.key == "react.hapy"


def test_a_missing_value_is_named():
    picker = PhrasePicker(shipped(), np.random.default_rng(0))
    with pytest.raises(PhraseError) as caught:
        picker.line("guess.pilot", toy="lion")
    assert str(caught.value).endswith(
        "en.toml: guess.pilot: expected values for {location}, {toy}, found {toy} "
        "(missing {location})"
    )


def test_an_extra_value_is_named():
    with pytest.raises(PhraseError) as caught:
        shipped().line("react.happy", np.random.default_rng(0), toy="lion")
    assert str(caught.value).endswith(
        "en.toml: react.happy: expected values for none, found {toy} (not allowed {toy})"
    )


def test_a_value_that_is_not_text_is_named():
    with pytest.raises(PhraseError) as caught:
        shipped().line("teach.move_arm", np.random.default_rng(0), bag=3)  # type: ignore[arg-type]
    assert str(caught.value).endswith("en.toml: teach.move_arm: expected text for {bag}, found int")


def test_a_bad_call_leaves_the_picker_untouched():
    book = shipped()
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    picker = PhrasePicker(book, rng_a)
    with pytest.raises(PhraseError):
        picker.line("guess.names")
    assert rng_a.integers(1000) == rng_b.integers(1000)


# Every load error, by its text -----------------------------------------------


def test_missing_key():
    document = broken(lambda d: d["react"].pop("happy"))
    assert error_of(document) == "fixture.toml: react.happy: required key is missing"


def test_missing_table():
    document = broken(lambda d: d.pop("confirm"))
    assert error_of(document) == "fixture.toml: confirm.start: required key is missing"


def test_missing_bands():
    document = broken(lambda d: d["uncertainty"].pop("bands"))
    assert error_of(document) == "fixture.toml: uncertainty.bands: required key is missing"


def test_empty_line_list():
    document = broken(lambda d: d["react"].update(happy=[]))
    assert error_of(document) == (
        "fixture.toml: react.happy: expected at least one line, found an empty array"
    )


def test_empty_line():
    document = broken(lambda d: d["react"].update(happy=["Yay", "  "]))
    assert error_of(document) == (
        "fixture.toml: react.happy[1]: expected a line to say, found an empty string"
    )


def test_repeated_variant():
    document = broken(lambda d: d["react"].update(happy=["Yay", "Hooray", "Yay"]))
    assert error_of(document) == (
        "fixture.toml: react.happy[2]: expected a different variant, found a repeat of react.happy[0]"
    )


def test_unknown_key_with_suggestion():
    document = broken(lambda d: d["react"].update(hapy=["Yay"]))
    assert (
        error_of(document) == "fixture.toml: react.hapy: unknown key; did you mean 'react.happy'?"
    )


def test_unknown_table():
    document = broken(lambda d: d.update(snacks={"crisps": ["Yum"]}))
    assert error_of(document) == "fixture.toml: snacks: unknown key"


def test_unknown_placeholder():
    document = broken(lambda d: d["guess"].update(names=["Is this the {toy}?", "Is it {tey}?"]))
    assert error_of(document) == (
        "fixture.toml: guess.names[1]: expected placeholders from {toy}, found {tey}"
    )


def test_placeholder_where_none_is_allowed():
    document = broken(lambda d: d["react"].update(happy=["Yay {child}!"]))
    assert error_of(document) == (
        "fixture.toml: react.happy[0]: expected placeholders from none, found {child}"
    )


def test_positional_placeholder():
    document = broken(lambda d: d["guess"].update(names=["Is this the {}?"]))
    assert error_of(document) == (
        "fixture.toml: guess.names[0]: expected placeholders from {toy}, found {}"
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


def test_bands_overlap():
    document = broken(lambda d: d["uncertainty"]["bands"][1].update(min=0.4))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[1].min: expected 0.5 (where band 'sure' ends), "
        "found 0.4: the bands overlap"
    )


def test_bands_leave_a_gap():
    document = broken(lambda d: d["uncertainty"]["bands"][2].update(min=1.2))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[2].min: expected 1.0 (where band 'fairly_sure' ends), "
        "found 1.2: the bands leave a gap"
    )


def test_bands_do_not_start_at_zero():
    document = broken(lambda d: d["uncertainty"]["bands"][0].update(min=0.1))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[0].min: expected 0 (the lowest band starts at 0 bits), "
        "found 0.1"
    )


def test_bands_do_not_end_at_inf():
    document = broken(lambda d: d["uncertainty"]["bands"][3].update(max=3.0))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[3].max: expected inf (the highest band covers "
        "everything above it), found 3.0"
    )


def test_band_min_not_below_max():
    document = broken(lambda d: d["uncertainty"]["bands"][1].update(max=0.5))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[1].max: expected more than min (0.5), found 0.5"
    )


def test_bands_in_any_order_are_sorted():
    document = broken(lambda d: d["uncertainty"]["bands"].reverse())
    book = parse(document)
    assert [band.name for band in book.bands] == ["sure", "fairly_sure", "idea_not_sure", "unsure"]
    assert book.band_for(1.5, 6) == "idea_not_sure"


def test_integer_band_limits_are_numbers():
    document = broken(lambda d: d["uncertainty"]["bands"][0].update(min=0))
    assert parse(document).bands[0].min == 0.0


def test_band_unknown_field():
    document = broken(lambda d: d["uncertainty"]["bands"][2].update(colour="red"))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[2].colour: unknown key; expected one of: "
        "name, min, max, lines"
    )


def test_band_missing_field():
    document = broken(lambda d: d["uncertainty"]["bands"][2].pop("lines"))
    assert error_of(document) == "fixture.toml: uncertainty.bands[2].lines: required key is missing"


def test_band_duplicate_name():
    document = broken(lambda d: d["uncertainty"]["bands"][1].update(name="sure"))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[1].name: expected a name not used by another band, "
        "found 'sure'"
    )


def test_band_name_that_shadows_a_key():
    document = broken(lambda d: d["uncertainty"]["bands"][1].update(name="no_idea"))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[1].name: expected a name other than 'no_idea', "
        "which is already a key"
    )


def test_band_placeholder_is_refused():
    document = broken(lambda d: d["uncertainty"]["bands"][0].update(lines=["Sure it's {toy}"]))
    assert error_of(document) == (
        "fixture.toml: uncertainty.bands[0].lines[0]: expected placeholders from none, found {toy}"
    )


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (
            lambda d: d["react"].update(happy="Yay"),
            "react.happy: expected an array of text, found a string ('Yay')",
        ),
        (
            lambda d: d["react"].update(happy=["Yay", 3]),
            "react.happy[1]: expected text, found an integer (3)",
        ),
        (
            lambda d: d.update(react=["Yay"]),
            "react: expected a table, found an array",
        ),
        (
            lambda d: d["uncertainty"]["bands"][0].update(min="zero"),
            "uncertainty.bands[0].min: expected a number of bits, found a string ('zero')",
        ),
        (
            lambda d: d["uncertainty"]["bands"][0].update(max=True),
            "uncertainty.bands[0].max: expected a number of bits, found a boolean (True)",
        ),
        (
            lambda d: d["uncertainty"]["bands"][0].update(min=math.nan),
            "uncertainty.bands[0].min: expected a number of bits, found nan",
        ),
        (
            lambda d: d["uncertainty"]["bands"][0].update(name=5),
            "uncertainty.bands[0].name: expected text, found an integer (5)",
        ),
        (
            lambda d: d["uncertainty"]["bands"][0].update(name="Very Sure"),
            "uncertainty.bands[0].name: expected a name like 'fairly_sure', found 'Very Sure'",
        ),
        (
            lambda d: d["uncertainty"].update(bands={"name": "sure"}),
            "uncertainty.bands: expected an array of tables ([[uncertainty.bands]]), found a table",
        ),
        (
            lambda d: d["uncertainty"].update(bands=[]),
            "uncertainty.bands: expected at least one band, found none",
        ),
    ],
)
def test_wrong_types(change, expected):
    assert error_of(broken(change)) == f"fixture.toml: {expected}"


def test_syntax_error():
    text = to_toml(valid_document()) + "\n[react\nhappy = 'x'\n"
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
    (tmp_path / "en.toml").write_text(to_toml(broken(lambda d: d["react"].pop("sad"))))
    with pytest.raises(PhraseError) as caught:
        load_phrasebook("en", str(tmp_path))
    assert str(caught.value) == f"{tmp_path / 'en.toml'}: react.sad: required key is missing"


def test_a_second_language_in_an_override_directory(tmp_path):
    document = valid_document()
    document["guess"]["names"] = [
        "Est-ce le {toy} ?",
        "C'est le {toy} ?",
        "Je crois que c'est le {toy}.",
    ]
    document["react"]["happy"] = ["Youpi !", "Bravo !", "Merci !"]
    (tmp_path / "fr.toml").write_text(to_toml(document), encoding="utf-8")
    book = load_phrasebook("fr", str(tmp_path))
    assert book.language == "fr"
    assert book.source == str(tmp_path / "fr.toml")
    rng = np.random.default_rng(0)
    assert book.line("guess.names", rng, toy="lion") in {
        "Est-ce le lion ?",
        "C'est le lion ?",
        "Je crois que c'est le lion.",
    }
    assert book.uncertainty(0.2, 6, rng)[0] == "sure"


def test_an_override_directory_replaces_the_shipped_english(tmp_path):
    (tmp_path / "en.toml").write_text(to_toml(valid_document()))
    book = load_phrasebook("en", str(tmp_path))
    assert book.source == str(tmp_path / "en.toml")
    assert book.variants("react.happy") == ("react.happy one ", "react.happy two ")


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
        book.lines["react.happy"] = ("x",)  # type: ignore[index]
