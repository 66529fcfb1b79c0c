"""What Kaspar says: phrases/<language>.toml into a validated, frozen phrase book.

Every line Kaspar can say has a dotted key ("react.happy") with a fixed set of
placeholders, listed once in REQUIRED_LINES. A file is checked completely when
it is loaded, so a typo in a placeholder fails `kasparctl check` at the desk
instead of in front of children. Errors name the file and the key, in the same
"FILE: KEY: expected X, found Y" style as kasparctl.config.

The book itself is immutable and takes an explicit random generator, so
simulations are reproducible; the only state, which variant was said last,
lives in a PhrasePicker owned by whoever is speaking.
"""

from __future__ import annotations

import difflib
import importlib.resources
import itertools
import math
import re
import string
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Final, NoReturn

import numpy as np


class PhraseError(Exception):
    """A phrase file that cannot be used, or a line asked for wrongly, with where and why."""

    def __init__(self, source: str, key: str, message: str) -> None:
        """Where (file, phrase key) and what is wrong."""
        super().__init__(f"{source}: {key}: {message}")
        self.source = source
        self.key = key
        self.message = message


@dataclass(frozen=True, slots=True)
class LineSpec:
    """What a line may contain, and how varied the shipped English file keeps it."""

    placeholders: frozenset[str] = frozenset()
    # Variants the shipped English file provides at least (checked by the tests,
    # not on load, so a new translation can start small).
    variety: int = 3


def _spec(*placeholders: str, variety: int = 3) -> LineSpec:
    return LineSpec(frozenset(placeholders), variety)


# Said before nearly every guess or answer, so they need the most variety.
_OFTEN: Final = 5

# The one table of what a phrase file must contain: adding a line is one entry.
# {bag} is the bag's number, {child} is "child one" or a first name, {joint} is
# a joint in spoken words; values are always text.
REQUIRED_LINES: Final[Mapping[str, LineSpec]] = MappingProxyType(
    {
        "session.greeting": _spec(),
        "session.intro_pilot": _spec(),
        "session.resumed": _spec(),
        "session.farewell": _spec(),
        "session.abandoned": _spec(),
        "steps.place_bags": _spec(),
        "steps.teach_pointing": _spec(),
        "steps.reveal_toys": _spec(),
        "steps.guessing": _spec(),
        "steps.farewell": _spec(),
        "teach.move_arm": _spec("bag", variety=_OFTEN),
        "teach.pose_logged": _spec("bag", variety=_OFTEN),
        "teach.try_again": _spec("bag"),
        "teach.swap_roles": _spec(),
        "teach.all_bags_done": _spec(),
        "guess.names": _spec("toy", variety=_OFTEN),
        "guess.pilot": _spec("toy", "location", variety=_OFTEN),
        "react.happy": _spec(variety=_OFTEN),
        "react.sad": _spec(variety=_OFTEN),
        "react.learned": _spec("toy"),
        "react.learned_pilot": _spec("toy", "location"),
        "react.all_learned": _spec(),
        "prompt.nobody_first": _spec(),
        "prompt.nobody_second": _spec(),
        "prompt.ask_researcher": _spec(),
        "turn.child": _spec("child", variety=_OFTEN),
        "confirm.start": _spec(),
        "confirm.next_step": _spec(),
        "confirm.pause": _spec(),
        "confirm.resume": _spec(),
        "confirm.undo": _spec(),
        "confirm.stop": _spec(),
        "fault.servo": _spec("joint"),
        "fault.keyfob_lost": _spec(),
        "fault.keyfob_back": _spec(),
        "fault.problem": _spec(),
        "fault.storage": _spec(),
        "fault.cleared": _spec(),
        "uncertainty.no_idea": _spec(variety=_OFTEN),
    }
)

# Bands are an array of tables; each band's lines are also reachable as the
# line key "uncertainty.<name>", so they are picked like any other line.
BANDS_KEY: Final = "uncertainty.bands"
BAND_LINE_PREFIX: Final = "uncertainty."
BAND_SPEC: Final = _spec(variety=_OFTEN)
NO_IDEA: Final = "no_idea"
_BAND_FIELDS: Final = ("name", "min", "max", "lines")
_BAND_NAME = re.compile(r"[a-z][a-z0-9_]*")

# How close to the maximum log2(n) counts as "no idea". Not 1e-9: entropies
# arrive rounded (the paper reports 2.585 for log2(6) = 2.58496 and 1.58 for
# log2(3)), and within 0.01 bits of uniform no listener could tell the
# difference anyway. The same margin above log2(n) is accepted as rounding.
NO_IDEA_TOLERANCE: Final = 0.01

_LANGUAGE = re.compile(r"[A-Za-z]{2,3}(?:[_-][A-Za-z0-9]{2,8})*")
_SHIPPED_PACKAGE: Final = "phrases"


@dataclass(frozen=True, slots=True)
class Band:
    """Entropies from min (included) to max (excluded), in bits."""

    name: str
    min: float
    max: float

    def contains(self, entropy_bits: float) -> bool:
        """Whether `entropy_bits` falls in this band."""
        return self.min <= entropy_bits < self.max


@dataclass(frozen=True)
class PhraseBook:
    """Every line of one language, validated; immutable, so it can be shared freely."""

    source: str
    language: str
    # Key -> variants, including "uncertainty.<band>" for every band.
    lines: Mapping[str, tuple[str, ...]]
    # Sorted from 0 up to inf.
    bands: tuple[Band, ...]
    placeholders: Mapping[str, frozenset[str]] = field(repr=False)

    @property
    def keys(self) -> tuple[str, ...]:
        """Every phrase key of the book."""
        return tuple(self.lines)

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
        variants = self.variants(key)
        if not 0 <= index < len(variants):
            self._fail(key, f"expected a variant index 0 to {len(variants) - 1}, found {index}")
        self.check_values(key, values)
        text = variants[index].format_map(values)
        # A line may open with a placeholder ("{child}, your turn"): still a sentence.
        return text[:1].upper() + text[1:]

    def band_for(
        self, entropy_bits: float, n_candidates: int, *, tolerance: float = NO_IDEA_TOLERANCE
    ) -> str:
        """The band name for an entropy over n candidates: NO_IDEA at the maximum."""
        if n_candidates < 1:
            self._fail("uncertainty", f"expected at least 1 candidate, found {n_candidates}")
        if not math.isfinite(entropy_bits) or entropy_bits < -tolerance:
            self._fail("uncertainty", f"expected an entropy >= 0 bits, found {entropy_bits}")
        maximum = math.log2(n_candidates)
        if entropy_bits > maximum + tolerance:
            self._fail(
                "uncertainty",
                f"expected an entropy <= log2({n_candidates}) = {maximum:.4f} bits, "
                f"found {entropy_bits}",
            )
        # With a single candidate there is nothing to be unsure about: 0 bits is "sure".
        if n_candidates > 1 and entropy_bits >= maximum - tolerance:
            return NO_IDEA
        clamped = max(entropy_bits, 0.0)
        # The bands cover [0, inf) without gaps (checked on load), so one always matches.
        return next(band.name for band in self.bands if band.contains(clamped))

    def uncertainty(
        self,
        entropy_bits: float,
        n_candidates: int,
        rng: np.random.Generator,
        *,
        tolerance: float = NO_IDEA_TOLERANCE,
    ) -> tuple[str, str]:
        """(band name, a line saying how sure Kaspar is), without repeat avoidance."""
        band = self.band_for(entropy_bits, n_candidates, tolerance=tolerance)
        return band, self.line(BAND_LINE_PREFIX + band, rng)

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


class PhrasePicker:
    """Picks lines from a book, never the same variant twice in a row for one key.

    The memory lives here, not in the book, so one book can serve a game, a
    simulation and `kasparctl say` at once without them disturbing each other.
    """

    def __init__(self, book: PhraseBook, rng: np.random.Generator) -> None:
        """Pick from `book`, drawing with `rng`."""
        self.book = book
        self._rng = rng
        self._last: dict[str, int] = {}

    def line(self, key: str, /, **values: str) -> str:
        """A variant of `key` filled in with `values`, not the one this picker said last."""
        variants = self.book.variants(key)
        # Validate before drawing, so a bad call neither consumes randomness nor memory.
        self.book.check_values(key, values)
        index = pick_index(len(variants), self._rng, avoid=self._last.get(key))
        self._last[key] = index
        return self.book.render(key, index, **values)

    def uncertainty(
        self, entropy_bits: float, n_candidates: int, *, tolerance: float = NO_IDEA_TOLERANCE
    ) -> tuple[str, str]:
        """(band name, line), the line not repeating the band's previous one."""
        band = self.book.band_for(entropy_bits, n_candidates, tolerance=tolerance)
        return band, self.line(BAND_LINE_PREFIX + band)


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


def load_phrasebook(language: str = "en", override_dir: str | None = None) -> PhraseBook:
    """The phrases for `language`: from override_dir if given, else the shipped ones."""
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
        return parse_phrasebook(data, str(path), language)
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
    return parse_phrasebook(data, str(resource), language)


def parse_phrasebook(data: bytes | str, source: str, language: str = "en") -> PhraseBook:
    """Validate a phrase file's text; `source` names it in errors."""

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
    for key in [*REQUIRED_LINES, BANDS_KEY]:
        if key not in found:
            fail(key, "required key is missing")

    lines = {key: _check_lines(found[key], key, spec, fail) for key, spec in REQUIRED_LINES.items()}
    placeholders = {key: spec.placeholders for key, spec in REQUIRED_LINES.items()}
    bands, band_lines = _check_bands(found[BANDS_KEY], fail)
    for band in bands:
        lines[BAND_LINE_PREFIX + band.name] = band_lines[band.name]
        placeholders[BAND_LINE_PREFIX + band.name] = BAND_SPEC.placeholders
    return PhraseBook(
        source=source,
        language=language,
        lines=MappingProxyType(lines),
        bands=bands,
        placeholders=MappingProxyType(placeholders),
    )


Fail = Callable[[str, str], NoReturn]

_KNOWN_LEAVES: Final = frozenset([*REQUIRED_LINES, BANDS_KEY])
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
        _check_format(text, where, spec.placeholders, fail)
    return tuple(value)


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


def _check_bands(value: Any, fail: Fail) -> tuple[tuple[Band, ...], dict[str, tuple[str, ...]]]:
    if not isinstance(value, list):
        fail(BANDS_KEY, f"expected an array of tables ([[{BANDS_KEY}]]), found {_toml_type(value)}")
    if not value:
        fail(BANDS_KEY, "expected at least one band, found none")
    indexed: list[tuple[int, Band]] = []
    band_lines: dict[str, tuple[str, ...]] = {}
    for index, table in enumerate(value):
        band, lines = _check_band(table, index, band_lines.keys(), fail)
        indexed.append((index, band))
        band_lines[band.name] = lines
    _check_coverage(indexed, fail)
    return tuple(band for _, band in sorted(indexed, key=lambda item: item[1].min)), band_lines


def _check_band(
    table: Any, index: int, taken: Iterable[str], fail: Fail
) -> tuple[Band, tuple[str, ...]]:
    where = f"{BANDS_KEY}[{index}]"
    if not isinstance(table, dict):
        fail(where, f"expected a table, found {_toml_type(table)}")
    for name in table:
        if name not in _BAND_FIELDS:
            fail(f"{where}.{name}", f"unknown key; expected one of: {', '.join(_BAND_FIELDS)}")
    for name in _BAND_FIELDS:
        if name not in table:
            fail(f"{where}.{name}", "required key is missing")
    name = table["name"]
    if not isinstance(name, str):
        fail(f"{where}.name", f"expected text, found {_toml_type(name)}")
    if not _BAND_NAME.fullmatch(name):
        fail(f"{where}.name", f"expected a name like 'fairly_sure', found {name!r}")
    # Band lines are reachable as "uncertainty.<name>", so a name must not shadow a key.
    if name == NO_IDEA or BAND_LINE_PREFIX + name in _KNOWN_LEAVES:
        fail(f"{where}.name", f"expected a name other than {name!r}, which is already a key")
    if name in taken:
        fail(f"{where}.name", f"expected a name not used by another band, found {name!r}")
    low = _number(table["min"], f"{where}.min", fail)
    high = _number(table["max"], f"{where}.max", fail)
    if low >= high:
        fail(f"{where}.max", f"expected more than min ({low}), found {high}")
    lines = _check_lines(table["lines"], f"{where}.lines", BAND_SPEC, fail)
    return Band(name, low, high), lines


def _check_coverage(indexed: list[tuple[int, Band]], fail: Fail) -> None:
    """Sorted by min, the bands must tile [0, inf) exactly."""
    ordered = sorted(indexed, key=lambda item: item[1].min)
    first_index, first = ordered[0]
    if first.min != 0.0:
        fail(
            f"{BANDS_KEY}[{first_index}].min",
            f"expected 0 (the lowest band starts at 0 bits), found {first.min}",
        )
    for (_, before), (index, band) in itertools.pairwise(ordered):
        if band.min != before.max:
            problem = "the bands overlap" if band.min < before.max else "the bands leave a gap"
            fail(
                f"{BANDS_KEY}[{index}].min",
                f"expected {before.max} (where band {before.name!r} ends), "
                f"found {band.min}: {problem}",
            )
    last_index, last = ordered[-1]
    if last.max != math.inf:
        fail(
            f"{BANDS_KEY}[{last_index}].max",
            f"expected inf (the highest band covers everything above it), found {last.max}",
        )


def _number(value: Any, key: str, fail: Fail) -> float:
    # bool is an int in Python, but `min = true` is a mistake, not 1.
    if isinstance(value, bool) or not isinstance(value, int | float):
        fail(key, f"expected a number of bits, found {_toml_type(value)}")
    if math.isnan(value):
        fail(key, "expected a number of bits, found nan")
    return float(value)


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
