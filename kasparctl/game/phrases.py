"""What Kaspar says: phrases/<language>.toml into a validated, frozen phrase book.

Every line Kaspar can say has a dotted key ("react.wrong") with a fixed set of
placeholders, listed once in REQUIRED_LINES with the limits it keeps and what
it is for (translators read that table). A file is checked completely when it
is loaded, so a typo in a placeholder fails `kasparctl check` at the desk
instead of in front of children. Errors name the file and the key, in the same
"FILE: KEY: expected X, found Y" style as kasparctl.config.

A key's first wording is the one the fixed script (`paper`, the default) says,
every time; the varied script picks among all of them, never the same twice
in a row. Lines are brief and literal: every sentence at most
MAX_SENTENCE_WORDS words, a line at most its LineSpec.max_sentences sentences
(two in step 4); `limit_problems` checks a book against them, in any language
(`sentences` splits French, German, Dutch and Italian as well as English).

How sure Kaspar is comes from kasparctl.game.scripts (the levels and their
limits are the study's, the same in every language); the book only words each
level, as the keys "uncertainty.<level>".

The book itself is immutable and takes an explicit random generator, so
simulations are reproducible; the only state, which variant was said last,
lives in a PhrasePicker owned by whoever is speaking.
"""

from __future__ import annotations

import difflib
import importlib.resources
import re
import string
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Final, NoReturn

import numpy as np

from hal.errors import KasparError
from kasparctl.game.scripts import (
    ALL_LEVELS,
    DEFAULT_SCRIPT,
    EXPLORING,
    LAST_ONE,
    LINE_PREFIX,
    SCRIPTS,
    SURE_LEFT,
)
from kasparctl.game.scripts import Band as Band  # figures shade a script's bands
from kasparctl.lexicon import TOY_FORMS, ToyWords, shipped_words


class PhraseError(KasparError):
    """A phrase file that cannot be used, or a line asked for wrongly, with where and why."""

    def __init__(self, source: str, key: str, message: str) -> None:
        """Where (file, phrase key) and what is wrong."""
        super().__init__(f"{source}: {key}: {message}")
        self.source = source
        self.key = key
        self.message = message


# Every sentence Kaspar says has at most this many words (placeholders filled in).
MAX_SENTENCE_WORDS: Final = 12
# Step 4 is said again and again: its lines are at most two sentences.
STEP4_SENTENCES: Final = 2


@dataclass(frozen=True, slots=True)
class LineSpec:
    """What a line may contain, how long it may be, and what it is for."""

    placeholders: frozenset[str] = frozenset()
    # Variants the shipped English file provides at least (checked by the tests,
    # not on load, so a new translation can start with one wording per key).
    variety: int = 1
    max_sentences: int = STEP4_SENTENCES
    about: str = ""


def _spec(*placeholders: str, variety: int = 1, sentences: int = 2, about: str = "") -> LineSpec:
    return LineSpec(frozenset(placeholders), variety, sentences, about)


# A placeholder the caller may leave out, and what it then says: the robot's name is
# known to the book only as its default (a game's picker gives the configured one).
DEFAULT_VALUES: Final[Mapping[str, str]] = MappingProxyType({"robot": "Kaspar"})

# Said before nearly every guess or answer: the varied script needs choices.
_OFTEN: Final = 3

# The one table of what a phrase file must contain: adding a line is one entry.
# Placeholders are filled with text: {bag} and {bags} a bag's number and how many
# there are ("3", "6"); {toy} a toy's name; {location} a pilot location's name;
# {where} how a location is said in a sentence ("in the box"); {child}, {mover},
# {presser} a child's first name or names.child; {number} a child's number; {robot} the
# robot's own name ([robot] name, "Kaspar" by default), in the greeting.
# A line whose key takes {toy} is given the toy's id and may say any of its forms
# (TOY_FORMS, kasparctl.lexicon): {toy} the noun alone, {the_toy} with its article.
REQUIRED_LINES: Final[Mapping[str, LineSpec]] = MappingProxyType(
    {
        "names.child": _spec(
            "number", sentences=1, about="a child without a first name, by number"
        ),
        "names.where": _spec(
            "location", sentences=1, about="a pilot location with no phrase of its own"
        ),
        "session.greeting": _spec(
            "robot", sentences=3, about="first words of a session ({robot}: [robot] name)"
        ),
        "session.resumed": _spec(about="a session carries on after a restart"),
        "session.thanks": _spec(sentences=3, about="the end of a session: thanks and goodbye"),
        "steps.place_bags": _spec("bags", about="step 1: the numbered bags go in places"),
        "steps.teach_pointing": _spec(about="step 2 begins"),
        "steps.reveal_toys": _spec(about="step 3: open the bags"),
        "steps.guessing": _spec(about="step 4 begins (names)"),
        "steps.pilot": _spec(about="step 4 begins (pilot: where the toys go)"),
        "steps.ready": _spec(about="steps 1 and 3: Kaspar has waited a long time"),
        "instructions.buttons": _spec(about="how to answer; again when nobody answers"),
        "instructions.teach": _spec(about="how to show a bag; again when nobody presses"),
        "teach.roles": _spec("mover", "presser", about="who moves the arm, who presses"),
        "teach.roles_alone": _spec("mover", about="one child does both jobs"),
        "teach.swap": _spec(about="the next round of step 2: new jobs"),
        "teach.bag_first": _spec("bag", about="the first bag of a round"),
        "teach.bag": _spec("bag", about="the next bag, shorter"),
        "teach.logged_first": _spec("bag", about="the first bag's pose is saved"),
        "teach.logged": _spec(about="a later bag's pose is saved, shorter"),
        "teach.try_again": _spec("bag", about="red while showing a bag"),
        "teach.out_of_reach": _spec("bag", about="the arm was shown where it cannot point"),
        "teach.check_again": _spec(
            "bag", about="shown far from where it was before; blames neither showing"
        ),
        "teach.not_moved": _spec(
            "bag", about="green with the arm at rest or at the bag before: asked again"
        ),
        "teach.all_done": _spec(about="step 2 is over"),
        "turn.first": _spec("child", about="a child's first turn in step 4"),
        "guess.names": _spec("child", "toy", variety=_OFTEN, about="the question (names)"),
        "guess.pilot": _spec(
            "child", "toy", "where", variety=_OFTEN, about="the question (pilot)"
        ),
        "react.right_check": _spec(
            "toy", variety=_OFTEN, about="green, not learned yet: no promise of the next guess"
        ),
        "react.right_check_pilot": _spec("toy", "where", about="the same in the pilot"),
        "react.learned": _spec("toy", variety=_OFTEN, about="green, and now it is learned"),
        "react.learned_pilot": _spec("toy", "where", about="the same in the pilot"),
        "react.wrong": _spec("toy", variety=_OFTEN, about="red: no promise of what comes"),
        "react.wrong_pilot": _spec("toy", "where", about="the same in the pilot"),
        "react.all_learned": _spec(about="every toy learned"),
        "react.all_learned_pilot": _spec(about="every toy's place learned"),
        "react.given_up": _spec(about="a toy not learned in its many guesses"),
        "prompt.answer_again": _spec("child", about="nobody answers, second prompt"),
        "prompt.teach": _spec("presser", "bag", about="nobody presses in step 2"),
        "prompt.ask_researcher": _spec(about="the last prompt: a grown-up is needed"),
        "listen.wait": _spec(about="a press before Kaspar finished asking"),
        "confirm.next_step": _spec(about="the researcher moved on"),
        "confirm.pause": _spec(about="the researcher paused"),
        "confirm.resume": _spec(about="the researcher resumed"),
        "confirm.undo": _spec(about="the researcher took the last answer back"),
        "confirm.stop": _spec(sentences=3, about="the researcher stopped: thanks, goodbye"),
        "confirm.close": _spec(about="a stopped session closed for good (no children)"),
        "confirm.reopen": _spec("toy", about="the researcher re-opened the name learned last"),
        "recovery.confused": _spec(
            about="every name left was answered red for this bag: asks for help, blames no one"
        ),
        "recovery.confused_learned": _spec(
            "toy", about="a name learned for another bag was answered green here"
        ),
        "recovery.ask_researcher": _spec(about="after confused: a grown-up may re-open a name"),
        "fault.servo": _spec(about="a joint failed (the joint goes to the records)"),
        "fault.keyfob_lost": _spec(about="the children's keyfob is gone"),
        "fault.keyfob_back": _spec(about="the children's keyfob is back"),
        "fault.researcher_lost": _spec(about="the researcher's keypad is gone"),
        "fault.researcher_back": _spec(about="the researcher's keypad is back"),
        "fault.remote_battery_low": _spec(about="a remote's battery is below its warning level"),
        "fault.keyfob_silent": _spec(
            about="to the grown-up: the children's keyfob sent nothing for a while (battery?)"
        ),
        "buttons.start": _spec(about="a session's start: Kaspar checks the buttons"),
        "buttons.green": _spec(about="the check: press green (again when nobody does)"),
        "buttons.red": _spec(about="the check: now press red (again when nobody does)"),
        "buttons.thanks": _spec(about="the check: both buttons work"),
        "fault.problem": _spec(about="any other fault"),
        "fault.storage": _spec(about="the records cannot be saved: a grown-up must stop"),
        "fault.battery_low": _spec(about="between trials: the battery fell below its line"),
        "session.abandoned": _spec(about="an unfinished session could not be resumed"),
        **{
            LINE_PREFIX + level: _spec(variety=_OFTEN, about=f"uncertainty level {level}")
            for level in ALL_LEVELS
        },
        LAST_ONE: _spec(variety=_OFTEN, about="varied script: only one name is left"),
        SURE_LEFT: _spec(variety=_OFTEN, about="varied script: sure, the others were wrong"),
        EXPLORING: _spec(
            variety=_OFTEN, about="instead of sure: the toy drawn is not the likeliest"
        ),
    }
)

# Where the uncertainty levels' limits once were: the study's, now in code.
_OLD_BANDS: Final = "uncertainty.bands"
_LANGUAGE = re.compile(r"[A-Za-z]{2,3}(?:[_-][A-Za-z0-9]{2,8})*")
_SHIPPED_PACKAGE: Final = "phrases"


@dataclass(frozen=True)
class PhraseBook:
    """Every line of one language, validated; immutable, so it can be shared freely."""

    source: str
    language: str
    # Key -> variants; the first is the fixed script's wording.
    lines: Mapping[str, tuple[str, ...]]
    placeholders: Mapping[str, frozenset[str]] = field(repr=False)
    # Toy id -> its words in this language ({toy}, {the_toy}); kasparctl.lexicon.
    toys: Mapping[str, ToyWords] = field(default_factory=dict, repr=False)

    @property
    def keys(self) -> tuple[str, ...]:
        """Every phrase key of the book."""
        return tuple(self.lines)

    @property
    def bands(self) -> tuple[Band, ...]:
        """The default script's levels below the maximum (for figures that shade them)."""
        return SCRIPTS[DEFAULT_SCRIPT].bands

    def variants(self, key: str) -> tuple[str, ...]:
        """The lines `key` may be said with; PhraseError for a key the book lacks."""
        if key not in self.lines:
            self._fail(key, _unknown_key_message(key, self.lines))
        return self.lines[key]

    def line(self, key: str, rng: np.random.Generator, /, **values: str) -> str:
        """Any variant of `key`, filled in. Use a PhrasePicker to avoid repeats."""
        variants = self.variants(key)
        # Checked before drawing, so a bad call consumes no randomness.
        self.check_values(key, values)
        return self.render(key, pick_index(len(variants), rng, avoid=None), **values)

    def render(self, key: str, index: int, /, **values: str) -> str:
        """Variant `index` of `key`, filled in; values must match the key's placeholders exactly."""
        text = self.fill(key, index, **values)
        # A sentence may open with a placeholder ("{child}, your turn"): still a sentence.
        return " ".join(said[:1].upper() + said[1:] for said in sentences(text, self.language))

    def fill(self, key: str, index: int = 0, /, **values: str) -> str:
        """Variant `index` of `key` filled in as it stands: for words said inside a line."""
        variants = self.variants(key)
        if not 0 <= index < len(variants):
            self._fail(key, f"expected a variant index 0 to {len(variants) - 1}, found {index}")
        values = {**self._defaults(key, values), **values}
        self.check_values(key, values)
        return variants[index].format_map(self._with_toy_forms(key, values))

    def _defaults(self, key: str, values: Mapping[str, str]) -> dict[str, str]:
        """The placeholders of `key` that have a default (DEFAULT_VALUES) and are not given."""
        allowed = self.placeholders[key]
        return {k: v for k, v in DEFAULT_VALUES.items() if k in allowed and k not in values}

    def _with_toy_forms(self, key: str, values: Mapping[str, str]) -> Mapping[str, str]:
        """`values` with the toy's id replaced by its forms in this book's language."""
        if "toy" not in values:
            return values
        toy = values["toy"]
        found = self.toys.get(toy)
        if found is None:
            if self.language != "en":
                known = ", ".join(sorted(self.toys)) or "none"
                self._fail(
                    key,
                    f"expected a toy with {self.language!r} words (phrases/toys/"
                    f"{self.language}.toml or [toy_names.{self.language}]: {known}), "
                    f"found {toy!r}",
                )
            # English says a toy it has no entry for as its id: "the teddy".
            found = ToyWords(name=toy, the=f"the {toy}")
        return {**values, **found.forms()}

    def check_values(self, key: str, values: Mapping[str, object]) -> None:
        """Raise PhraseError unless `values` fill exactly the placeholders allowed for `key`."""
        # Checked against the key, not the chosen variant, so a wrong call fails
        # every time rather than only when a particular variant is drawn.
        allowed = self.placeholders[key]
        missing = sorted(allowed - values.keys())
        extra = sorted(values.keys() - allowed)
        if missing or extra:
            self._fail(
                key,
                f"expected values for {_braces(allowed)}, found {_braces(values)}"
                + (f" (missing {_braces(missing)})" if missing else "")
                + (f" (not allowed {_braces(extra)})" if extra else ""),
            )
        for name, value in values.items():
            if not isinstance(value, str):
                self._fail(key, f"expected text for {{{name}}}, found {type(value).__name__}")

    def _fail(self, key: str, message: str) -> NoReturn:
        raise PhraseError(self.source, key, message)


# Limits ----------------------------------------------------------------------

# A sentence ends at . ! ? … (or the CJK marks), with any closing quotes or
# brackets, before white space or the end. French puts a space before ? and !
# ("C'est le lion ?"): the mark still ends the sentence, the space before it
# does not split anything. Decimals and times ("1.5", "10:30") have no space
# after the point. Abbreviations ("z. B.", "bijv.") would split: lines avoid them.
_SENTENCE_END = re.compile(
    "[.!?\u2026\u3002\uff01\uff1f]+[\"'\u00bb\u201d\u2019)\\]]*(?=\\s|$)"
)
# A word holds a letter or a digit: "l'enfant", "Est-ce", "3", "1.5" are words; "?" is not.
_WORD = re.compile("[^\\W_](?:[\\w'\u2019\\-]*[^\\W_])?(?:[.,]\\d+)*")


def sentences(text: str, language: str = "en") -> list[str]:
    """The sentences of a line, in order, each with its end mark.

    `language` is the phrase book's: the rule is the same for the languages Kaspar
    speaks (en, nl, de, it, fr), which all end sentences with . ! ? (French with a
    space before ? and !); it is an argument so a language that needs its own rule
    can have one without changing the callers.
    """
    del language  # one rule serves them all, for now
    parts, start = [], 0
    for end in _SENTENCE_END.finditer(text):
        parts.append(text[start : end.end()].strip())
        start = end.end()
    parts.append(text[start:].strip())
    return [part for part in parts if part]


def word_count(sentence: str) -> int:
    """The words of a sentence: runs holding a letter or digit (punctuation is no word)."""
    return len(_WORD.findall(sentence))


def limit_problems(book: PhraseBook, values: Mapping[str, str]) -> list[str]:
    """Every line of `book` that breaks its limits, filled with `values`, as "key[i]: why".

    `values` gives each placeholder its longest plausible text in the book's
    language (a two-word first name, the longest toy, "on the shelf"), so the
    limits hold for the sentences children will hear.
    """
    problems = []
    for key, variants in book.lines.items():
        spec = REQUIRED_LINES.get(key, _spec())
        filled = {
            name: values.get(name, DEFAULT_VALUES.get(name, "")) for name in book.placeholders[key]
        }
        for index in range(len(variants)):
            said = sentences(book.fill(key, index, **filled), book.language)
            if len(said) > spec.max_sentences:
                problems.append(
                    f"{key}[{index}]: expected at most {spec.max_sentences} sentences, "
                    f"found {len(said)}: {said}"
                )
            for sentence in said:
                words = word_count(sentence)
                if words > MAX_SENTENCE_WORDS:
                    problems.append(
                        f"{key}[{index}]: expected at most {MAX_SENTENCE_WORDS} words in a "
                        f"sentence, found {words}: {sentence!r}"
                    )
    return problems


class PhrasePicker:
    """Picks lines from a book: the first wording every time (`fixed`), or varied, never
    the same variant twice in a row for one key.

    The memory lives here, not in the book, so one book can serve a game, a
    simulation and `kasparctl say` at once without them disturbing each other.
    """

    def __init__(self, book: PhraseBook, rng: np.random.Generator, *, fixed: bool = False) -> None:
        """Pick from `book`, drawing with `rng` (never, when `fixed`)."""
        self.book = book
        self.fixed = fixed
        # The robot's name ([robot] name), said where a line has {robot} (the greeting).
        self.robot = "Kaspar"
        self._rng = rng
        self._last: dict[str, int] = {}

    def line(self, key: str, /, **values: str) -> str:
        """A variant of `key` filled in with `values`: the first when fixed, else not the
        one this picker said last."""
        variants = self.book.variants(key)
        if "robot" in self.book.placeholders[key] and "robot" not in values:
            values = {**values, "robot": self.robot}  # this robot's own name
        # Validate before drawing, so a bad call neither consumes randomness nor memory.
        self.book.check_values(key, values)
        if self.fixed:
            return self.book.render(key, 0, **values)
        index = pick_index(len(variants), self._rng, avoid=self._last.get(key))
        self._last[key] = index
        return self.book.render(key, index, **values)


def pick_index(count: int, rng: np.random.Generator, avoid: int | None) -> int:
    """A uniform index in range(count), other than `avoid` when there is a choice."""
    if count == 1:
        return 0
    if avoid is None or not 0 <= avoid < count:
        return int(rng.integers(count))
    # Draw among the others and step over `avoid`: uniform, and one draw only.
    index = int(rng.integers(count - 1))
    return index + 1 if index >= avoid else index


# Loading ---------------------------------------------------------------------


def load_phrasebook(
    language: str = "en",
    override_dir: str | None = None,
    toys: Mapping[str, ToyWords] | None = None,
) -> PhraseBook:
    """The phrases for `language`: from override_dir if given, else the shipped ones.

    `toys` are the words of the configuration's toys (Config.toy_words); without them
    the book says the toys of the shipped lexicon of `language`.
    """
    where = override_dir if override_dir is not None else _SHIPPED_PACKAGE
    if not _LANGUAGE.fullmatch(language):
        # Also keeps a language like "../x" from reading outside the directory.
        raise PhraseError(
            where, "language", f"expected a language code such as 'en', found {language!r}"
        )
    filename = f"{language}.toml"
    if override_dir is not None:
        path = Path(override_dir) / filename
        try:
            data = path.read_bytes()
        except OSError as error:
            raise PhraseError(str(path), "(file)", f"cannot read it: {error.strerror}") from error
        return parse_phrasebook(data, str(path), language, toys)
    resource = importlib.resources.files(_SHIPPED_PACKAGE) / filename
    try:
        data = resource.read_bytes()
    except OSError as error:
        shipped = sorted(
            entry.name.removesuffix(".toml")
            for entry in importlib.resources.files(_SHIPPED_PACKAGE).iterdir()
            if entry.name.endswith(".toml")
        )
        raise PhraseError(
            str(resource),
            "(file)",
            f"expected one of the shipped languages ({', '.join(shipped)}), found {language!r}",
        ) from error
    return parse_phrasebook(data, str(resource), language, toys)


def parse_phrasebook(
    data: bytes | str,
    source: str,
    language: str = "en",
    toys: Mapping[str, ToyWords] | None = None,
) -> PhraseBook:
    """Validate a phrase file's text; `source` names it in errors. `toys` as in
    load_phrasebook."""

    def fail(key: str, message: str) -> NoReturn:
        raise PhraseError(source, key, message)

    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError as error:
            fail("(file)", f"expected UTF-8 text, found {error.reason} at byte {error.start}")
    try:
        document = tomllib.loads(data)
    except tomllib.TOMLDecodeError as error:
        fail("(syntax)", f"not valid TOML: {error}")

    found: dict[str, Any] = {}
    _collect(document, "", found, fail)
    for key in REQUIRED_LINES:
        if key not in found:
            fail(key, "required key is missing")

    lines = {key: _check_lines(found[key], key, spec, fail) for key, spec in REQUIRED_LINES.items()}
    placeholders = {key: spec.placeholders for key, spec in REQUIRED_LINES.items()}
    return PhraseBook(
        source=source,
        language=language,
        lines=MappingProxyType(lines),
        placeholders=MappingProxyType(placeholders),
        toys=MappingProxyType(dict(shipped_words(language) if toys is None else toys)),
    )


Fail = Callable[[str, str], NoReturn]

_KNOWN_LEAVES: Final = frozenset(REQUIRED_LINES)
# Every table on the way to a known key, e.g. "react" for "react.happy".
_KNOWN_TABLES: Final = frozenset(
    key.rsplit(".", depth)[0] for key in _KNOWN_LEAVES for depth in range(1, key.count(".") + 1)
)


def _collect(table: Mapping[str, Any], prefix: str, found: dict[str, Any], fail: Fail) -> None:
    """Flatten the document into dotted keys, rejecting anything not in REQUIRED_LINES."""
    for name, value in table.items():
        key = f"{prefix}.{name}" if prefix else name
        if key in _KNOWN_LEAVES:
            found[key] = value
        elif key == _OLD_BANDS:
            fail(
                key,
                "the uncertainty levels and their limits are no longer in the phrase book "
                "(they are the study's: kasparctl/game/scripts.py); give each level its "
                f"lines as {', '.join(LINE_PREFIX + level for level in ALL_LEVELS)}",
            )
        elif key in _KNOWN_TABLES:
            if not isinstance(value, dict):
                fail(key, f"expected a table, found {_toml_type(value)}")
            _collect(value, key, found, fail)
        else:
            fail(key, _unknown_key_message(key, _KNOWN_LEAVES))


def _check_lines(value: Any, key: str, spec: LineSpec, fail: Fail) -> tuple[str, ...]:
    if not isinstance(value, list):
        fail(key, f"expected an array of text, found {_toml_type(value)}")
    if not value:
        fail(key, "expected at least one line, found an empty array")
    seen: dict[str, int] = {}
    for index, text in enumerate(value):
        where = f"{key}[{index}]"
        if not isinstance(text, str):
            fail(where, f"expected text, found {_toml_type(text)}")
        if not text.strip():
            fail(where, "expected a line to say, found an empty string")
        if text in seen:
            fail(where, f"expected a different variant, found a repeat of {key}[{seen[text]}]")
        seen[text] = index
        _check_format(text, where, _sayable(spec.placeholders), fail)
    return tuple(value)


def _sayable(placeholders: frozenset[str]) -> frozenset[str]:
    """What a line may say: its key's placeholders, and every form of a toy it is given."""
    return placeholders | frozenset(TOY_FORMS) if "toy" in placeholders else placeholders


def _check_format(text: str, key: str, allowed: frozenset[str], fail: Fail) -> None:
    try:
        fields = list(string.Formatter().parse(text))
    except ValueError as error:
        fail(
            key,
            f"expected {{name}} placeholders or {{{{ }}}} for braces, "
            f"found a malformed one ({error})",
        )
    for _literal, name, format_spec, conversion in fields:
        if name is None:
            continue
        if name not in allowed:
            fail(key, f"expected placeholders from {_braces(allowed)}, found {{{name}}}")
        # Speech has no use for "!r" or ":>5", and they would fail only at runtime.
        if format_spec or conversion:
            fail(key, f"expected a plain {{{name}}}, found a conversion or format spec in it")


def _toml_type(value: Any) -> str:
    """The TOML name of a parsed value, as a file's author would call it."""
    names: list[tuple[type | tuple[type, ...], str]] = [
        (bool, "a boolean"),
        (int, "an integer"),
        (float, "a float"),
        (str, "a string"),
        (list, "an array"),
        (dict, "a table"),
    ]
    for kind, name in names:
        if isinstance(value, kind):
            return f"{name} ({value!r})" if kind in (bool, int, float, str) else name
    return type(value).__name__


def _unknown_key_message(key: str, known: Iterable[str]) -> str:
    close = difflib.get_close_matches(key, list(known), n=1)
    return f"unknown key; did you mean {close[0]!r}?" if close else "unknown key"


def _braces(names: Iterable[str]) -> str:
    ordered = sorted(names)
    return ", ".join(f"{{{name}}}" for name in ordered) if ordered else "none"
