"""Words the configuration and the game share: the researcher's commands, the group limit.

A leaf module (it imports nothing of the project), so kasparctl.config can
validate against the very enum the game acts on without importing the game.
"""

from __future__ import annotations

import enum


class Command(enum.StrEnum):
    """What the researcher can tell the game with a keyfob gesture (game.commands)."""

    NEXT = "next"
    PAUSE = "pause"
    UNDO = "undo"
    STOP = "stop"
    # Re-open the name learned last: it is offered again and its bag asked again
    # (kasparctl.game.recovery). Kaspar asks for it when it is confused.
    REOPEN = "reopen"
    # One shared keyfob: take the child whose turn it is out of the rotation (a child who
    # left); given right after a child's skipped turn, bring that child back
    # (kasparctl.game.rotation).
    AWAY = "away"
    # In idle, before a session: step to the next planned session, and mark the chosen
    # one's group absent (or take the mark back) without opening it (kasparctl.game.opening).
    CHOOSE = "choose"
    ABSENT = "absent"


# Commands a session cannot be run without: every configuration must map a gesture to each.
REQUIRED_COMMANDS = (Command.NEXT, Command.PAUSE, Command.STOP)

# The most children a group may have (the paper's groups had two or three). A child
# without a first name is called by the phrase book's names.child ("child 2").
MAX_CHILDREN = 6

# Cells that R (read.csv: "NA"; readr: "" and "NA") or pandas (read_csv's default
# na_values) read as missing. A code or a name that is one of them would come back as a
# missing value in an analysis, so the configuration refuses them, and an export writes
# any such text recorded before with a leading "'" (kasparctl.research.tidy.cell).
MISSING_MARKERS = frozenset(
    {
        "", "#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "-nan", "1.#IND",
        "1.#QNAN", "<NA>", "N/A", "NA", "NULL", "NaN", "None", "n/a", "nan", "null",
    }
)
