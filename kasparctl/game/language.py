"""The language a game is played in: its phrase book with its toys' words, and its voice.

kaspar.toml's `language` chooses all three (docs/languages.md); a command's
`--language` plays the same configuration in another language, with that
language's voice and toys, checked as the file's own language is.
"""

from __future__ import annotations

import re

import msgspec

from hal.voice.settings import voice_for_language
from kasparctl.config import Config, ConfigError
from kasparctl.game.phrases import PhraseBook, load_phrasebook
from kasparctl.lexicon import LexiconError

_LANGUAGE = re.compile(r"[A-Za-z]{2,3}(?:[_-][A-Za-z0-9]{2,8})*")


def phrasebook_for(config: Config) -> PhraseBook:
    """The phrase book of the configured language, saying the configured toys' words.

    PhraseError for a phrase file that cannot be used; a toy without words in the
    language was refused when the configuration was read.
    """
    return load_phrasebook(config.language, config.phrases_dir, config.toy_words())


def with_language(config: Config, language: str, source: str = "--language") -> Config:
    """`config` spoken in `language`: its language, and the voice of that language.

    ConfigError (keyed by the missing toy, as when reading a file) when a configured
    toy has no words in `language`; `source` names where the language was asked for.
    """
    if not _LANGUAGE.fullmatch(language):
        raise ConfigError(
            source, "language", f"expected a language code such as 'de', found {language!r}"
        )
    if language == config.language:
        return config
    try:
        config.toy_words(language, source)
    except LexiconError as error:
        raise ConfigError(error.source, error.key, error.message) from error
    voice = msgspec.structs.replace(config.voice, voice=voice_for_language(language))
    return msgspec.structs.replace(config, language=language, voice=voice)
