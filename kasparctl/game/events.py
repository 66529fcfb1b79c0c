"""What the game tells its listeners: the daemon's status line, the demo's narrator,
the simulated children and the tests all follow the game through these events.

A listener is called synchronously with the event and a dict of details; it
must not block (it runs on the game's own task). A listener that raises is
logged and left out of that event: it never stops the game.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from typing import Any


class GameEvent(enum.StrEnum):
    """An event a Game emits; the comment says which details come with it."""

    STATE = "state"  # state: the stage the machine entered
    SESSION = "session"  # session: the id of the session just opened
    RESUMED = "resumed"  # step: the stage the resumed session carries on in
    WAITING_FOR_RESEARCHER = "waiting_for_researcher"  # step: idle, placing or revealing
    # Kaspar starts asking: in step 4 trial, target, choice (indices), child and its
    # child_index; in step 2 bag, round, mover, presser (children's names); in the check
    # of the buttons button_check (the button asked for). Presses are early until it ends.
    ASKING = "asking"
    # bag, round, mover, presser: Kaspar has asked for bag's pose (from 0) and waits.
    TEACH = "teach"
    POINT = "point"  # target: the name Kaspar points at; style: "slowly, hesitating"...
    # What the game asked of Kaspar's body (kasparctl.game.bodywork): kind "look" (gaze,
    # index, name), "perform" (behaviour, strength) or "alive" (alive).
    BODY = "body"
    # target, choice (indices), trial, child, child_index: the question is finished,
    # Kaspar listens.
    QUESTION = "question"
    LISTENING = "listening"  # (none): Kaspar shows it listens (its pose, its sound)
    PROMPT = "prompt"  # line: the prompt's phrase key (nobody answered)
    # button: at the start of a session Kaspar has asked for this button and listens
    # (kasparctl.game.buttons); the press is no answer to any question.
    BUTTON_CHECK = "button_check"
    ANSWERED = "answered"  # trial, feedback: the answer is recorded
    FAULT = "fault"  # kind: the FaultSource that stopped the game
    KEYFOB_BACK = "keyfob_back"  # (none): the keyfob is read again
    RESUME_REFUSED = "resume_refused"  # (none): a resume from a fault failed to rearm
    # problems: FaultSource -> detail, every part that is not working now (empty: all well);
    # sent whenever it changes (the daemon's STATUS= shows it)
    PROBLEMS = "problems"
    # target (index), reason, learned ([(target, label)...], the one learned last at the
    # end): Kaspar is confused and asks the researcher (kasparctl.game.recovery).
    CONFUSED = "confused"
    # target, name (indices): the researcher re-opened the name learned last.
    REOPENED = "reopened"
    # target, toy (names): the right toy of an open target is no longer offered.
    ALERT = "alert"
    # group, number, absent: the researcher chose a planned session in idle, or marked
    # its group absent (absent true) or took the mark back
    CHOSEN = "chosen"
    # change, child: a child taken out of step 4's rotation ("away") or brought back
    ROTATION = "rotation"


Listener = Callable[[GameEvent, dict[str, Any]], None]
