"""Toys in each language: the words a sentence needs for a toy, from a shipped lexicon.

A toy is known to the game by its id ("lion": game.toys, the records, the
answer key, the research tables); what Kaspar *says* for it comes from the
lexicon of the session's language: phrases/toys/<language>.toml, shipped, and
the `[toy_names.<language>]` table of kaspar.toml, which adds toys or overrides
shipped ones. Each entry gives the noun (`name`), its grammatical gender where
the language has one (`gender`), and optionally its definite form (`the`); the
definite form is otherwise made by the language's rule (`definite`).

The phrase books use two forms, so lines never need a case other than the
nominative or a preposition fused with an article (German "den Löwen",
French "du lion", Italian "del leone" are avoided by how the lines are
written): {toy}, the noun alone ("Löwe"), and {the_toy}, the noun with its
definite article as a subject or after "is" ("der Löwe", "l'éléphant",
"lo scoiattolo", "het paard"). docs/languages.md has the rules and the format.

A leaf room (floor 1): kasparctl.config validates against it, the game fills
lines from it.
"""

from __future__ import annotations

import functools
import importlib.resources
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import msgspec

from hal.errors import KasparError

# The languages Kaspar ships a phrase book, a toy lexicon and a voice for.
SHIPPED_LANGUAGES: Final = ("en", "nl", "de", "it", "fr")
# The genders a toy may have, per language; a language not listed has none to give,
# and its entries must say their definite form (`the`) themselves.
GENDERS: Final[Mapping[str, tuple[str, ...]]] = {
    "en": (),
    "nl": ("m", "f", "n"),
    "de": ("m", "f", "n"),
    "fr": ("m", "f"),
    "it": ("m", "f"),
}
_GENDER_WORDS: Final = {"m": "masculine", "f": "feminine", "n": "neuter"}
_PACKAGE: Final = "phrases"
_FOLDER: Final = "toys"
_LANGUAGE = re.compile(r"[A-Za-z]{2,3}(?:[_-][A-Za-z0-9]{2,8})*")


class LexiconError(KasparError):
    """A toy without the words a line needs, or a lexicon entry that cannot be used."""

    def __init__(self, source: str, key: str, message: str) -> None:
        """Where (file, key) and what is wrong, as "FILE: KEY: expected X, found Y"."""
        super().__init__(f"{source}: {key}: {message}")
        self.source = source
        self.key = key
        self.message = message


class ToyEntry(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """One toy in one language as a file writes it: `lion = { name = "Löwe", gender = "m" }`."""

    # The noun alone, as said in a sentence ("Löwe", "éléphant").
    name: str
    # m, f or n, as GENDERS allows for the language; none in English.
    gender: str | None = None
    # The definite form, nominative ("der Löwe"); made from name and gender when not given.
    the: str | None = None


@dataclass(frozen=True, slots=True)
class ToyWords:
    """What Kaspar says for one toy in one language: {toy} and {the_toy}."""

    name: str
    the: str
    gender: str | None = None

    def forms(self) -> dict[str, str]:
        """The phrase placeholders this toy fills."""
        return {"toy": self.name, "the_toy": self.the}


# The placeholders a toy fills: a line with {toy} in its key may use each.
TOY_FORMS: Final = ("toy", "the_toy")

_DE_ARTICLES: Final = {"m": "der", "f": "die", "n": "das"}
# French and Italian elide the article before a vowel (and French before a mute h:
# "l'hippopotame"; an aspirated h, "le hibou", is written out in `the`).
_FR_ELIDES = re.compile(r"(?i)^[aeiouyhàâäéèêëîïôöùûüœæ]")
_IT_ELIDES = re.compile(r"(?i)^[aeiouàèéìíòóùú]")
# Italian "lo": before s + consonant, z, x, y, gn, ps, pn, and i or j before a vowel.
_IT_LO = re.compile(r"(?i)^(s[^aeiouàèéìòù]|z|x|y|gn|ps|pn|[ij][aeiouàèéìòù])")


def definite(language: str, name: str, gender: str | None) -> str | None:
    """The definite nominative of `name` by the language's rule; None if it has none.

    en: "the lion"; de: der/die/das; nl: de (m, f) or het (n); fr: le/la, l' before
    a vowel or h; it: il/lo/la, l' before a vowel. Exceptions go in an entry's `the`.
    """
    if language == "en":
        return f"the {name}"
    if gender is None:
        return None
    if language == "de":
        return f"{_DE_ARTICLES[gender]} {name}"
    if language == "nl":
        return f"{'het' if gender == 'n' else 'de'} {name}"
    if language == "fr":
        if _FR_ELIDES.match(name):
            return f"l'{name}"
        return f"{'le' if gender == 'm' else 'la'} {name}"
    if language == "it":
        if _IT_ELIDES.match(name):
            return f"l'{name}"
        if gender == "f":
            return f"la {name}"
        return f"{'lo' if _IT_LO.match(name) else 'il'} {name}"
    return None


def words(entry: ToyEntry, language: str, source: str, key: str) -> ToyWords:
    """An entry's words in `language`, checked; LexiconError names `key` in `source`."""

    def fail(where: str, message: str) -> LexiconError:
        return LexiconError(source, where, message)

    if not entry.name.strip() or not entry.name.isprintable() or entry.name != entry.name.strip():
        raise fail(f"{key}.name", f"expected a word to say, found {entry.name!r}")
    genders = GENDERS.get(language)
    if entry.gender is not None:
        if genders is not None and entry.gender not in genders:
            allowed = ", ".join(f"{g} ({_GENDER_WORDS[g]})" for g in genders) or "none"
            found = repr(entry.gender)
            raise fail(f"{key}.gender", f"expected one of {allowed} in {language!r}, found {found}")
    elif genders and entry.the is None:
        raise fail(
            f"{key}.gender",
            f"expected a gender ({', '.join(genders)}) or the definite form `the`, found neither",
        )
    the = entry.the if entry.the is not None else definite(language, entry.name, entry.gender)
    if the is None:
        raise fail(
            f"{key}.the",
            f"expected the definite form (no rule makes it in {language!r}), found none",
        )
    if not the.strip() or not the.isprintable() or the != the.strip():
        raise fail(f"{key}.the", f"expected the words to say, found {the!r}")
    return ToyWords(name=entry.name, the=the, gender=entry.gender)


def shipped_source(language: str) -> str:
    """Where the shipped lexicon of `language` is (for messages)."""
    return f"{_PACKAGE}/{_FOLDER}/{language}.toml"


@functools.cache
def shipped_entries(language: str) -> Mapping[str, ToyEntry]:
    """The shipped lexicon of `language` (toy id -> entry); empty for a language without one."""
    if not _LANGUAGE.fullmatch(language):
        return {}
    resource = importlib.resources.files(_PACKAGE) / _FOLDER / f"{language}.toml"
    try:
        data = resource.read_bytes()
    except OSError:
        return {}
    return parse_entries(data, shipped_source(language))


def shipped_words(language: str) -> dict[str, ToyWords]:
    """Every toy of the shipped lexicon of `language`, with its words."""
    source = shipped_source(language)
    return {
        toy: words(entry, language, source, toy) for toy, entry in shipped_entries(language).items()
    }


def parse_entries(data: bytes | str, source: str) -> dict[str, ToyEntry]:
    """A lexicon file's entries (toy id -> entry); LexiconError names a bad one."""
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
        document: dict[str, Any] = tomllib.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise LexiconError(source, "(file)", f"expected UTF-8 TOML, found: {error}") from error
    entries = {}
    for toy, value in document.items():
        try:
            entries[toy] = msgspec.convert(value, type=ToyEntry)
        except msgspec.ValidationError as error:
            raise LexiconError(
                source, toy, f"expected {{ name = ..., gender = ..., the = ... }}, found: {error}"
            ) from error
    return entries


def resolve(
    language: str,
    toys: tuple[str, ...],
    overrides: Mapping[str, ToyEntry],
    source: str,
) -> dict[str, ToyWords]:
    """The words of each of `toys` in `language`: the configuration's entry, else the
    shipped one; an English toy without either is said as its id ("the teddy").

    LexiconError, keyed `toy_names.<language>.<toy>` in `source`, for a toy with no
    words in a language that needs them, or an unusable entry.
    """
    shipped = shipped_entries(language)
    found: dict[str, ToyWords] = {}
    for toy in toys:
        key = f"toy_names.{language}.{toy}"
        if toy in overrides:
            found[toy] = words(overrides[toy], language, source, key)
        elif toy in shipped:
            found[toy] = words(shipped[toy], language, shipped_source(language), toy)
        elif language == "en":
            found[toy] = words(ToyEntry(name=toy), language, source, key)
        else:
            genders = GENDERS.get(language) or ()
            example = (
                f'{{ name = "...", gender = "{genders[0]}" }}'
                if genders
                else '{ name = "...", the = "..." }'
            )
            known = ", ".join(sorted(shipped)) or "none"
            raise LexiconError(
                source,
                key,
                f"expected the {language!r} words for toy {toy!r} (add [toy_names.{language}] "
                f"{toy} = {example}), found none: {shipped_source(language)} has {known}",
            )
    return found
