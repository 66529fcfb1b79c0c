"""How Kaspar says how sure it is: the uncertainty scripts, as rules, apart from their words.

The paper (section IV) has three levels: at the maximum entropy Kaspar has no
idea, around 1.5 bits it has an idea but is not sure, below 0.5 bits it is
sure. That is the `paper` script, the default, for replication: one fixed line
per level, and every other line of the game in its first wording too (a fixed
script, the same for every group). `varied` is the richer alternative: five
levels (the bands this project used before scripts existed, so sessions
recorded then resume with the same band names) and varied wordings, with
lines that say why Kaspar is sure when it is sure by elimination.

A level is chosen by the entropy alone, so it is the research variable (the
trial's `band`); the line said for it may also depend on the state (one name
left; sure without a green yet) and on the toy drawn (Eq. 2 may draw a toy other
than the likeliest even when the entropy is low: then a confident level says
"I want to try another name." instead), so the words never contradict the state
or the guess that follows them.
The levels' limits live here and not in the phrase books: they are the
study's, the same in every language.

Each script has a version, recorded in every session's plan with the script's
name: change a script's rules or its lines' meaning and raise its version.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from hal.errors import KasparError

# How close to the maximum log2(n) counts as "no idea". Not 1e-9: entropies
# arrive rounded (the paper reports 2.585 for log2(6) = 2.58496 and 1.58 for
# log2(3)), and within 0.01 bits of uniform no listener could tell the
# difference anyway. The same margin above log2(n) is accepted as rounding.
NO_IDEA_TOLERANCE: Final = 0.01
NO_IDEA: Final = "no_idea"
# The level of entropies below 0.5 bits, in every script (paper: "sure").
SURE: Final = "sure"
# Phrase keys of the uncertainty lines: "uncertainty.<level>", and the two the
# varied script says instead of "sure" when the state says why.
LINE_PREFIX: Final = "uncertainty."
LAST_ONE: Final = "uncertainty.last_one"
SURE_LEFT: Final = "uncertainty.sure_left"
# Said instead of a level that claims knowledge when the toy about to be named is not
# the one Kaspar thinks likeliest (Eq. 2 drew another): "I am sure." then a toy of
# p = 0.008 would contradict itself. The band recorded stays the entropy's.
EXPLORING: Final = "uncertainty.exploring"
# The levels whose lines say Kaspar knows (or nearly knows) the answer.
CONFIDENT_LEVELS: Final = (SURE, "fairly_sure")
DEFAULT_SCRIPT: Final = "paper"
# What a session recorded before scripts existed said: the five bands, varied.
LEGACY_SCRIPT: Final = "varied"


class ScriptError(KasparError, ValueError):
    """An entropy no distribution over the candidates can have, or an unknown script."""


@dataclass(frozen=True, slots=True)
class Band:
    """Entropies from min (included) to max (excluded), in bits: one level of a script."""

    name: str
    min: float
    max: float

    def contains(self, entropy_bits: float) -> bool:
        """Whether `entropy_bits` falls in this band."""
        return self.min <= entropy_bits < self.max


@dataclass(frozen=True, slots=True)
class Script:
    """One uncertainty script: its levels (bands below the maximum) and how it words them."""

    name: str
    version: int
    # Sorted from 0 up to inf, without gaps; NO_IDEA is the maximum, above them all.
    bands: tuple[Band, ...]
    # Every line in its first wording (the paper's), or wordings varied.
    fixed: bool
    # Sure by elimination said as such (LAST_ONE, SURE_LEFT), not as "sure".
    says_why: bool

    @property
    def levels(self) -> tuple[str, ...]:
        """Every level this script can say, NO_IDEA first."""
        return (NO_IDEA, *(band.name for band in reversed(self.bands)))

    def level(
        self, entropy_bits: float, n_candidates: int, *, tolerance: float = NO_IDEA_TOLERANCE
    ) -> str:
        """The level of an entropy over `n_candidates`: NO_IDEA at the maximum.

        ScriptError for an entropy outside [0, log2(n)] (beyond `tolerance`).
        """
        if n_candidates < 1:
            raise ScriptError(f"expected at least 1 candidate, found {n_candidates}")
        if not math.isfinite(entropy_bits) or entropy_bits < -tolerance:
            raise ScriptError(f"expected an entropy >= 0 bits, found {entropy_bits}")
        maximum = math.log2(n_candidates)
        if entropy_bits > maximum + tolerance:
            raise ScriptError(
                f"expected an entropy <= log2({n_candidates}) = {maximum:.4f} bits, "
                f"found {entropy_bits}"
            )
        # With a single candidate there is nothing to be unsure about: 0 bits is "sure".
        if n_candidates > 1 and entropy_bits >= maximum - tolerance:
            return NO_IDEA
        clamped = max(entropy_bits, 0.0)
        return next(band.name for band in self.bands if band.contains(clamped))

    def line_key(
        self, level: str, n_candidates: int, confirmed: bool, favourite: bool = True
    ) -> str:
        """The phrase key Kaspar says for `level`.

        `confirmed`: the toy it is about to name had a green on this target already
        (sure because the children said so, not by elimination). `favourite`: it is
        the likeliest candidate; when it is not, a confident level says EXPLORING.
        """
        if self.says_why and n_candidates == 1:
            return LAST_ONE
        if level in CONFIDENT_LEVELS and not favourite:
            return EXPLORING
        if self.says_why and level == SURE and not confirmed:
            return SURE_LEFT
        return LINE_PREFIX + level


SCRIPTS: Final[Mapping[str, Script]] = MappingProxyType(
    {
        "paper": Script(
            name="paper",
            # 2: a confident level before a toy that is not the likeliest says EXPLORING.
            version=2,
            bands=(Band(SURE, 0.0, 0.5), Band("idea_not_sure", 0.5, math.inf)),
            fixed=True,
            says_why=False,
        ),
        "varied": Script(
            name="varied",
            version=2,
            bands=(
                Band(SURE, 0.0, 0.5),
                Band("fairly_sure", 0.5, 1.0),
                Band("idea_not_sure", 1.0, 2.0),
                Band("unsure", 2.0, math.inf),
            ),
            fixed=False,
            says_why=True,
        ),
    }
)
# Every level any script says: the phrase books give lines for each.
ALL_LEVELS: Final = tuple(
    dict.fromkeys(level for script in SCRIPTS.values() for level in script.levels)
)


def script(name: str) -> Script:
    """The script called `name`; ScriptError naming the known ones otherwise."""
    try:
        return SCRIPTS[name]
    except KeyError:
        raise ScriptError(
            f"expected a script, one of {', '.join(SCRIPTS)}, found {name!r}"
        ) from None
