"""Kaspar in Dutch, German, Italian and French beside English: complete phrase books, toys
said with their articles, every line rendered by real espeak-ng, a whole demo game spoken
in the language and nothing in English, the language on the plan and every CSV row."""

from __future__ import annotations

import asyncio
import csv
import json
import re
import string
import tomllib
import wave
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from hal.voice.espeak import espeak_argv, write_wav
from hal.voice.settings import LANGUAGE_VOICES
from kasparctl.cli import main
from kasparctl.config import ConfigError, parse_config
from kasparctl.game.language import phrasebook_for, with_language
from kasparctl.game.phrases import PhraseBook, limit_problems, load_phrasebook
from kasparctl.lexicon import SHIPPED_LANGUAGES, definite, shipped_words
from kasparctl.sim.demo import demo_config

ROOT = Path(__file__).resolve().parents[1]
PHRASES = ROOT / "phrases"
OTHERS = [language for language in SHIPPED_LANGUAGES if language != "en"]
# The longest each placeholder plausibly is in each language (a two-word first name, a
# long location phrase); toys are swept one by one.
LONGEST: dict[str, dict[str, str]] = {
    "en": {"location": "bookshelf", "where": "on the top shelf"},
    "nl": {"location": "boekenkast", "where": "op de bovenste plank"},
    "de": {"location": "Bücherregal", "where": "auf das oberste Regal"},
    "it": {"location": "libreria", "where": "sul ripiano più alto"},
    "fr": {"location": "bibliothèque", "where": "sur l'étagère du haut"},
}
COMMON = {"bag": "6", "bags": "6", "child": "Anna Maria", "mover": "Anna Maria",
          "presser": "Anna Maria", "number": "6", "robot": "Kaspar"}  # fmt: skip
# A child's first name that is nobody's word, so the transcript checks see only Kaspar's.
SAMPLE = {"bag": "3", "bags": "6", "child": "Sam", "mover": "Sam", "presser": "Ali",
          "number": "2", "location": "Xylo", "robot": "Kaspar"}  # fmt: skip
# espeak-ng at Kaspar's 150 words a minute says a character in about 70 ms (measured:
# 39 to 149 ms over every line of the five books; the most, "Kind 2", says its digit as
# a word): a line well outside this band is cut short, silent or stuck.
SECONDS_PER_CHARACTER = (0.03, 0.2)


def flat(document: dict[str, Any], prefix: str = "") -> dict[str, list[str]]:
    found: dict[str, list[str]] = {}
    for name, value in document.items():
        if isinstance(value, dict):
            found.update(flat(value, f"{prefix}{name}."))
        else:
            found[prefix + name] = value
    return found


def raw(language: str) -> dict[str, list[str]]:
    return flat(tomllib.loads((PHRASES / f"{language}.toml").read_text(encoding="utf-8")))


def fields(text: str) -> set[str]:
    return {name for _, name, _, _ in string.Formatter().parse(text) if name}


def said_values(language: str, key: str, book: PhraseBook, toy: str) -> dict[str, str]:
    values = {**SAMPLE, "toy": toy, "where": LONGEST[language]["where"]}
    return {name: values[name] for name in book.placeholders[key]}


# --- the books: complete, the same shape as English, every placeholder filled -----------


@pytest.mark.parametrize("language", OTHERS)
def test_every_key_of_english_and_no_other(language: str) -> None:
    english, translated = raw("en"), raw(language)
    assert sorted(set(english) - set(translated)) == []  # missing
    assert sorted(set(translated) - set(english)) == []  # extra
    load_phrasebook(language)  # and it loads: placeholders, repeats, types


@pytest.mark.parametrize("language", OTHERS)
def test_the_same_variants_and_levels_as_english(language: str) -> None:
    english, translated = raw("en"), raw(language)
    counts = {key: (len(english[key]), len(translated[key])) for key in english}
    assert {key: both for key, both in counts.items() if both[0] != both[1]} == {}
    # The entropy levels: every level the scripts say is worded, as in English.
    levels = sorted(key for key in english if key.startswith("uncertainty."))
    assert sorted(key for key in translated if key.startswith("uncertainty.")) == levels


@pytest.mark.parametrize("language", OTHERS)
def test_each_variant_says_what_its_english_says(language: str) -> None:
    """The same placeholders, variant by variant ({toy} or {the_toy} for the toy): a line
    that names the child, the bag or the toy in English names it in the translation."""
    english, translated = raw("en"), raw(language)

    def said(text: str) -> set[str]:
        return {"toy" if name == "the_toy" else name for name in fields(text)}

    differ = [
        f"{key}[{index}]"
        for key in english
        for index, (en, other) in enumerate(zip(english[key], translated[key], strict=True))
        if said(en) != said(other)
    ]
    assert differ == []


@pytest.mark.parametrize("language", SHIPPED_LANGUAGES)
def test_every_line_keeps_the_limits_with_every_toy(language: str) -> None:
    book = load_phrasebook(language)
    assert len(book.toys) >= 12
    for toy in book.toys:
        values = {**COMMON, **LONGEST[language], "toy": toy}
        assert limit_problems(book, values) == [], toy


@pytest.mark.parametrize("language", SHIPPED_LANGUAGES)
def test_every_placeholder_is_filled_for_every_toy(language: str) -> None:
    book = load_phrasebook(language)
    for key, variants in book.lines.items():
        for index in range(len(variants)):
            variant = variants[index]
            toys = book.toys.items() if "toy" in book.placeholders[key] else [("", None)]
            for toy, words in toys:
                text = book.render(key, index, **said_values(language, key, book, toy))
                assert "{" not in text and "}" not in text, (key, index, toy)
                if words is not None and "the_toy" in fields(variant):
                    assert words.the.lower() in text.lower(), (key, index, toy, text)
                if words is not None and fields(variant) & {"toy", "the_toy"}:
                    assert words.name.lower() in text.lower(), (key, index, toy, text)


# --- toys and their grammar ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("language", "toy", "the"),
    [
        ("en", "lion", "the lion"),
        ("de", "lion", "der Löwe"), ("de", "giraffe", "die Giraffe"), ("de", "zebra", "das Zebra"),
        ("nl", "lion", "de leeuw"), ("nl", "horse", "het paard"), ("nl", "cat", "de kat"),
        ("fr", "lion", "le lion"), ("fr", "giraffe", "la girafe"), ("fr", "elephant", "l'éléphant"),
        ("fr", "bear", "l'ours"),
        ("it", "lion", "il leone"), ("it", "elephant", "l'elefante"), ("it", "giraffe", "la giraffa"),
        ("it", "duck", "l'anatra"),
    ],
)  # fmt: skip
def test_shipped_toys_have_their_articles(language: str, toy: str, the: str) -> None:
    assert shipped_words(language)[toy].the == the


@pytest.mark.parametrize(
    ("language", "name", "gender", "the"),
    [
        ("it", "scoiattolo", "m", "lo scoiattolo"), ("it", "zaino", "m", "lo zaino"),
        ("it", "gnomo", "m", "lo gnomo"), ("it", "psicologo", "m", "lo psicologo"),
        ("it", "orso", "m", "l'orso"), ("it", "aquila", "f", "l'aquila"),
        ("it", "treno", "m", "il treno"), ("it", "palla", "f", "la palla"),
        ("fr", "hippopotame", "m", "l'hippopotame"), ("fr", "autruche", "f", "l'autruche"),
        ("fr", "balle", "f", "la balle"), ("de", "Auto", "n", "das Auto"),
        ("nl", "konijn", "n", "het konijn"), ("nl", "bal", "m", "de bal"),
    ],
)  # fmt: skip
def test_the_article_rules(language: str, name: str, gender: str, the: str) -> None:
    assert definite(language, name, gender) == the


GERMAN_BALL = """
language = "de"
[game]
toys = ["lion", "ball", "hibou"]
"""


def test_a_toy_without_words_in_the_language_is_named_exactly() -> None:
    with pytest.raises(ConfigError) as error:
        parse_config(GERMAN_BALL, "kaspar.toml")
    assert str(error.value) == (
        "kaspar.toml: toy_names.de.ball: expected the 'de' words for toy 'ball' (add "
        '[toy_names.de] ball = { name = "...", gender = "m" }), found none: '
        "phrases/toys/de.toml has bear, cat, crocodile, dog, duck, elephant, frog, giraffe, "
        "horse, lion, monkey, zebra"
    )


def test_kaspar_toml_adds_and_overrides_toys() -> None:
    config = parse_config(
        GERMAN_BALL
        + '[toy_names.de]\nball = { name = "Ball", gender = "m" }\n'
        + 'hibou = { name = "Eule", gender = "f" }\nlion = { name = "Löwin", gender = "f" }\n'
        + '[toy_names.fr]\nhibou = { name = "hibou", gender = "m", the = "le hibou" }\n',
        "kaspar.toml",
    )
    book = phrasebook_for(config)
    assert book.render("guess.names", 0, child="Sam", toy="ball") == "Sam, ist es der Ball?"
    assert book.render("react.wrong", 1, toy="lion") == "Es ist nicht die Löwin. Danke."
    assert book.render("guess.names", 2, child="Sam", toy="hibou") == "Ist das die Eule, Sam?"
    # The French entry is checked too, though the robot speaks German.
    with pytest.raises(ConfigError, match=r"toy_names\.fr\.hibou\.gender: expected one of m "):
        parse_config(
            GERMAN_BALL + '[toy_names.fr]\nhibou = { name = "hibou", gender = "n" }\n', "k.toml"
        )


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ('{ name = "Ball", gender = "x" }',
         "k.toml: toy_names.de.ball.gender: expected one of m (masculine), f (feminine), "
         "n (neuter) in 'de', found 'x'"),
        ('{ name = "Ball" }',
         "k.toml: toy_names.de.ball.gender: expected a gender (m, f, n) or the definite form "
         "`the`, found neither"),
        ('{ name = " Ball", gender = "m" }',
         "k.toml: toy_names.de.ball.name: expected a word to say, found ' Ball'"),
    ],
)  # fmt: skip
def test_a_bad_toy_entry_is_named(entry: str, expected: str) -> None:
    with pytest.raises(ConfigError) as error:
        parse_config(GERMAN_BALL + f"[toy_names.de]\nball = {entry}\nhibou = {entry}\n", "k.toml")
    assert str(error.value) == expected


def test_an_unknown_entry_field_is_named() -> None:
    with pytest.raises(ConfigError) as error:
        parse_config(GERMAN_BALL + '[toy_names.de.ball]\nname = "Ball"\nplural = "Bälle"\n', "k")
    assert (
        str(error.value)
        == "k: toy_names.de.ball.plural: unknown key; expected one of: name, gender, the"
    )


def test_english_says_a_toy_of_no_lexicon_as_its_id() -> None:
    config = parse_config('[game]\ntoys = ["teddy", "lion"]\n', "k.toml")
    book = phrasebook_for(config)
    assert book.render("react.learned", 0, toy="teddy") == "Hooray! I know the teddy."


def test_another_language_refuses_a_toy_it_has_no_words_for() -> None:
    book = load_phrasebook("de")
    with pytest.raises(Exception, match=r"guess.names: expected a toy with 'de' words .* 'teddy'"):
        book.render("guess.names", 0, child="Sam", toy="teddy")


# --- the voice follows the language -------------------------------------------------------


@pytest.mark.parametrize("language", SHIPPED_LANGUAGES)
def test_the_voice_follows_the_language_unless_configured(language: str) -> None:
    assert parse_config(f'language = "{language}"\n', "k").voice.voice == LANGUAGE_VOICES[language]
    named = parse_config(f'language = "{language}"\n[voice]\nvoice = "mb-x"\n', "k")
    assert named.voice.voice == "mb-x"


def test_a_language_on_the_command_line_brings_its_voice_and_checks_the_toys() -> None:
    german = with_language(demo_config(), "de")
    assert (german.language, german.voice.voice) == ("de", "de")
    teddy = parse_config('[game]\ntoys = ["teddy", "lion"]\n', "k.toml")
    with pytest.raises(ConfigError, match=r"--language: toy_names\.it\.teddy: expected the 'it'"):
        with_language(teddy, "it")


def test_say_speaks_with_the_languages_voice(tmp_path: Path, capsys) -> None:
    wav = tmp_path / "hallo.wav"
    assert main(["say", "--language", "de", "--wav", str(wav), "Hallo, ich bin Kaspar."]) == 0
    assert "wrote" in capsys.readouterr().out and wav.read_bytes()[:4] == b"RIFF"
    with pytest.raises(SystemExit) as usage:
        main(["say", "--language", "-x", "Hallo"])
    assert usage.value.code == 2


# --- every line, every toy, through real espeak-ng ----------------------------------------


def sweep(language: str) -> Iterator[tuple[str, str]]:
    """(where, text): every variant of every key once; toy lines cycle through the toys
    until every toy has been said too."""
    book = load_phrasebook(language)
    toys = list(book.toys)
    turn = 0
    for key, variants in book.lines.items():
        takes_toy = "toy" in book.placeholders[key]
        for index in range(len(variants)):
            toy = toys[turn % len(toys)] if takes_toy else ""
            turn += takes_toy
            yield (
                f"{key}[{index}] {toy}",
                book.render(key, index, **said_values(language, key, book, toy)),
            )
    for toy in toys[turn:]:
        yield f"guess.names[0] {toy}", book.render("guess.names", 0, child="Sam", toy=toy)


def wav_seconds(path: Path) -> tuple[float, float]:
    """The WAV's spoken span (from its first sound to its last: espeak-ng ends every
    line with a pause, which would swamp a short line) and its RMS level (16-bit)."""
    with wave.open(str(path)) as sound:
        frames = sound.readframes(sound.getnframes())
        rate = sound.getframerate()
    samples = np.frombuffer(frames, dtype="<i2").astype(float)
    loud = np.flatnonzero(np.abs(samples) > 500)
    if not loud.size:
        return 0.0, 0.0
    span = samples[loud[0] : loud[-1] + 1]
    return span.size / rate, float(np.sqrt(np.mean(span**2)))


@pytest.mark.parametrize("language", SHIPPED_LANGUAGES)
def test_every_line_renders_with_real_espeak_ng(language: str, tmp_path: Path) -> None:
    config = parse_config(f'language = "{language}"\n', "k")
    argv = espeak_argv(config.voice)
    assert argv[argv.index("-v") + 1] == LANGUAGE_VOICES[language]
    lines = list(sweep(language))
    said_toys = {where.split(" ")[1] for where, _ in lines if where.split(" ")[1]}
    assert said_toys == set(load_phrasebook(language).toys)

    async def render_all() -> None:
        for number, (_, text) in enumerate(lines):
            await write_wav(argv, tmp_path / f"{number}.wav", text)

    asyncio.run(render_all())
    low, high = SECONDS_PER_CHARACTER
    odd, rates = [], []
    for number, (where, text) in enumerate(lines):
        seconds, level = wav_seconds(tmp_path / f"{number}.wav")
        per_character = seconds / len(text)
        rates.append(per_character)
        if not low <= per_character <= high or level < 300:
            odd.append(
                f"{where}: {text!r}: {seconds:.2f} s, {per_character:.3f} s/char, {level:.0f}"
            )
    print(f"{language}: {len(lines)} lines, s/char min {min(rates):.3f} "
          f"median {float(np.median(rates)):.3f} max {max(rates):.3f}")  # fmt: skip
    assert odd == []


# --- a whole game in the language, and nothing in English ---------------------------------


def line_patterns(book: PhraseBook) -> list[re.Pattern[str]]:
    """Every variant of the book as a pattern a spoken line matches (any values)."""
    patterns = []
    for variants in book.lines.values():
        for text in variants:
            parts = [
                re.escape(literal) + ("(.+?)" if name is not None else "")
                for literal, name, _, _ in string.Formatter().parse(text)
            ]
            patterns.append(re.compile("".join(parts), re.IGNORECASE))
    return patterns


def spoken(out: str) -> list[str]:
    return [line.split("Kaspar: ", 1)[1] for line in out.splitlines() if "] Kaspar: " in line]


def matches_a_line(text: str, patterns: list[re.Pattern[str]]) -> bool:
    return any(pattern.fullmatch(text) for pattern in patterns)


ENGLISH_TOYS = {words.name for words in shipped_words("en").values()}


@pytest.mark.parametrize("variant", ["names", "pilot"])
@pytest.mark.parametrize("language", OTHERS)
def test_a_whole_demo_game_in_the_language(
    language: str, variant: str, tmp_path: Path, capsys
) -> None:
    arguments = ["demo", "--fast", "--json", "--seed", "5", "--state-dir", str(tmp_path)]
    assert main([*arguments, "--language", language, "--variant", variant]) == 0
    out = capsys.readouterr().out
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["finished"] is True and summary["trials"] >= 6
    said = spoken(out)
    assert len(said) > 30
    # Every line Kaspar spoke is a line of the language's book...
    own = line_patterns(load_phrasebook(language))
    assert [text for text in said if not matches_a_line(text, own)] == []
    # ...and none is an English line, or names a toy in English.
    english = line_patterns(load_phrasebook("en"))
    assert [text for text in said if matches_a_line(text, english)] == []
    local = {words.name.lower() for words in shipped_words(language).values()}
    foreign = {name for name in ENGLISH_TOYS if name.lower() not in local}
    named = [
        (name, text)
        for text in said
        for name in foreign
        if re.search(rf"\b{re.escape(name)}\b", text, re.IGNORECASE)
    ]
    assert named == []
    # Toys were said with their articles.
    forms = [words.the.lower() for words in shipped_words(language).values()]
    assert any(the in text.lower() for text in said for the in forms)
    # The language is on the plan and on every row of the export.
    plan = json.loads((tmp_path / "sessions" / summary["session"] / "plan.json").read_text())
    assert plan["language"] == language
    trials, events = tmp_path / "trials.csv", tmp_path / "events.csv"
    export = ["export", "--state-dir", str(tmp_path), "--csv", str(trials), "--events", str(events)]
    assert main(export) == 0
    for path in (trials, events):
        with path.open(newline="", encoding="utf-8") as stream:
            rows = list(csv.DictReader(stream))
        assert rows and {row["language"] for row in rows} == {language}


# --- as a new user: the German example configuration -------------------------------------

EXAMPLE = ROOT / "docs" / "examples" / "kaspar-de.toml"


def example(tmp_path: Path) -> Path:
    """The example with its state and sound kept in tmp_path (as the docs say to change)."""
    text = EXAMPLE.read_text(encoding="utf-8")
    text = text.replace('state_dir = "/var/lib/kaspar"', f'state_dir = "{tmp_path / "state"}"')
    wavs = tmp_path / "wavs"
    wavs.mkdir()
    text = text.replace("[voice]\n", f'[voice]\nwav_dir = "{wavs}"\n')
    path = tmp_path / "kaspar.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_german_example_checks_and_speaks_german(tmp_path: Path, capsys) -> None:
    path = example(tmp_path)
    config = parse_config(path.read_text(encoding="utf-8"), str(path))
    assert (config.language, config.voice.voice) == ("de", "de")
    assert main(["check", "--config", str(path)]) == 0
    out = capsys.readouterr().out
    assert (
        "voice          ok    spoke the test line via espeak-ng (language 'de', voice 'de')" in out
    )
    (wav,) = (tmp_path / "wavs").glob("*.wav")
    seconds, _ = wav_seconds(wav)
    greeting = phrasebook_for(config).render("session.greeting", 0)
    assert greeting.startswith("Hallo. Ich bin Kaspar.")
    low, high = SECONDS_PER_CHARACTER
    assert low <= seconds / len(greeting) <= high


def test_the_german_example_plays_a_german_game(tmp_path: Path, capsys) -> None:
    path = example(tmp_path)
    state = tmp_path / "demo"
    arguments = ["demo", "--fast", "--json", "--seed", "4", "--state-dir", str(state)]
    assert main([*arguments, "--config", str(path)]) == 0
    out = capsys.readouterr().out
    said = spoken(out)
    config = parse_config(path.read_text(encoding="utf-8"), str(path))
    own = line_patterns(phrasebook_for(config))
    assert [text for text in said if not matches_a_line(text, own)] == []
    english = line_patterns(load_phrasebook("en"))
    assert [text for text in said if matches_a_line(text, english)] == []
    # The example's own toy, from its [toy_names.de], is said with its article.
    assert any("der Ball" in text for text in said)
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["finished"] is True


def test_old_sessions_read_as_english(tmp_path: Path) -> None:
    state = ROOT / "tests" / "data" / "sessions-v1" / "state"
    trials = tmp_path / "trials.csv"
    assert main(["export", "--state-dir", str(state), "--csv", str(trials)]) == 0
    with trials.open(newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert rows and {row["language"] for row in rows} == {"en"}


def test_a_plan_records_its_language() -> None:
    from kasparctl.config import SessionPlan
    from kasparctl.game.opening import planned

    config = with_language(demo_config(), "it")
    assert planned(config, SessionPlan(group="g"), 1)["language"] == "it"
    assert (
        msgspec.json.decode(msgspec.json.encode(planned(demo_config(), SessionPlan(group="g"), 1)))[
            "language"
        ]
        == "en"
    )


@pytest.mark.parametrize("language", SHIPPED_LANGUAGES)
def test_pyttsx3_finds_each_languages_voice(language: str) -> None:
    pyttsx3 = pytest.importorskip("pyttsx3")
    from hal.voice.pyttsx3_thread import _voice_id

    engine = pyttsx3.init()
    voice = _voice_id(engine, LANGUAGE_VOICES[language])
    assert voice.rsplit("/", 1)[-1] == {"en": "en", "fr": "fr"}.get(language, language)


def test_a_reload_that_changes_the_language_is_applied(tmp_path: Path) -> None:
    """A reload between sessions takes the new language with its voice (the voice is
    configured again), so German words are never said by the English voice."""
    from service_fixtures import run_command, running_service
    from test_service_faults import quick_speaker, reload

    runtime = tmp_path / "run"
    runtime.mkdir(mode=0o700)
    config = quick_speaker(tmp_path)
    env = {"RUNTIME_DIRECTORY": str(runtime)}
    with running_service(
        tmp_path, env, command=lambda state: run_command(state, config=config)
    ) as service:
        service.notify.wait_for("READY=1")
        text = config.read_text(encoding="utf-8").replace('language = "en"', 'language = "de"', 1)
        config.write_text(text, encoding="utf-8")
        reloaded = reload(service.process.pid, runtime)
        assert reloaded.returncode == 0, reloaded.stderr
        assert service.process.poll() is None
        assert service.stop() == 0
