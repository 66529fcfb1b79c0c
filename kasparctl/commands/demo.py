"""`kasparctl demo`: the whole game on simulated hardware with simulated children.

Kaspar's lines, the children's presses and the robot's movements are printed
as they happen, each with its clock time. Everything is recorded in a state
directory, exactly as on the robot; an unfinished session there is resumed.
The demo is that directory's one writer while it runs: a state directory in use
(by the service, or another demo) is refused at once.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import secrets
import sys
import tempfile
from pathlib import Path
from typing import Any, TextIO, cast

from kasparctl.commands.arguments import (
    PROBABILITY,
    UsageError,
    language,
    number,
    output_file,
    path,
    seed,
    stdin_readable,
)
from kasparctl.config import UNCERTAINTY_MODES, Config, load_config
from kasparctl.game.language import with_language
from kasparctl.game.lock import StateDirLock
from kasparctl.log import configure_logging
from kasparctl.sim.children import Interruptions
from kasparctl.sim.demo import (
    DemoOptions,
    DemoResult,
    Transcript,
    demo_config,
    run_demo,
    with_variant,
)
from kasparctl.sim.teacher import DEFAULT_THINK_S, Messiness, Teacher, load_teacher

# Slower than real time down to a thousandth; faster up to a million times (beyond, the
# clock's steps are below what the loop can time: use --fast).
SPEED = number(0.001, 1e6)


def register(subparsers: Any) -> None:
    """Add the `demo` subcommand."""
    parser = subparsers.add_parser(
        "demo", help="watch a simulated group of children teach Kaspar", description=__doc__
    )
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument(
        "--speed", type=SPEED, default=None, help="run the clock F times faster (0.001 to 1e6)"
    )
    timing.add_argument("--fast", action="store_true", help="simulated time, as fast as possible")
    parser.add_argument("--seed", type=seed, default=None, help="reproduce a game exactly")
    parser.add_argument(
        "--interactive", action="store_true", help="you are the children: keys on the terminal"
    )
    parser.add_argument(
        "--state-dir", default=None, type=path,
        help="keep the records here (default: a new temporary dir)",
    )  # fmt: skip
    parser.add_argument(
        "--config", default=None, type=path, help="kaspar.toml (default: the demo robot)"
    )
    parser.add_argument("--variant", choices=("names", "pilot"), default=None)
    parser.add_argument(
        "--language",
        type=language,
        default=None,
        metavar="L",
        help="Kaspar speaks L (en, nl, de, it, fr): its phrases, toys and voice",
    )
    parser.add_argument(
        "--uncertainty",
        choices=UNCERTAINTY_MODES,
        default=None,
        help="how Kaspar shows how sure it is: said, by its body, both or neither "
        "(default: the session plan's; a resumed session keeps its own)",
    )
    parser.add_argument("--p-wrong-green", type=PROBABILITY, default=0.0)
    parser.add_argument("--p-wrong-red", type=PROBABILITY, default=0.0)
    parser.add_argument("--p-no-answer", type=PROBABILITY, default=0.0)
    parser.add_argument(
        "--teacher",
        default=None,
        type=path,
        metavar="FILE",
        help="children answering as a teacher model (`kasparctl fit-teacher`): its rates "
        "pooled, its reaction times",
    )
    # Messy children, per answer: a hold, a double tap, both buttons, a press while
    # Kaspar is still asking. None of it may become a researcher's command.
    parser.add_argument("--p-hold", type=PROBABILITY, default=0.0, help="an answer held 0.6-5 s")
    parser.add_argument("--p-double", type=PROBABILITY, default=0.0, help="an answer pressed twice")
    parser.add_argument("--p-both", type=PROBABILITY, default=0.0, help="both buttons squeezed")
    parser.add_argument(
        "--p-early", type=PROBABILITY, default=0.0, help="a press while Kaspar asks"
    )
    parser.add_argument(
        "--p-unmoved-arm", type=PROBABILITY, default=0.0,
        help="step 2: green pressed before anyone moved Kaspar's arm (Kaspar asks again)",
    )  # fmt: skip
    # The researcher interrupting at any moment, open questions included: none of it may
    # become the children's answer (commands_taken_as_answers in --json).
    parser.add_argument(
        "--p-researcher-pause", type=PROBABILITY, default=0.0,
        help="per question: the researcher pauses at any moment, and resumes later",
    )  # fmt: skip
    parser.add_argument(
        "--p-researcher-undo", type=PROBABILITY, default=0.0,
        help="per answer: the researcher undoes it a moment later",
    )  # fmt: skip
    parser.add_argument(
        "--p-researcher-stop", type=PROBABILITY, default=0.0,
        help="per question: the researcher stops the session at any moment",
    )  # fmt: skip
    parser.add_argument(
        "--json", action="store_true", help="end with one JSON line summarising the game"
    )
    parser.add_argument("--motion", type=output_file, metavar="CSV", help="write every goal each "
                        "joint received: time_s, joint, position_deg, source (session clock)")
    parser.add_argument("--voice", choices=("espeak-ng", "pyttsx3"), help="also say every line "
                        "with this engine, into WAV files (<state-dir>/voice, or voice.wav_dir)")
    parser.add_argument(
        "--view",
        action="store_true",
        help="draw the game as `kasparctl watch` does (on a terminal; else the transcript)",
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Play the whole game on the simulated robot with simulated children."""
    if arguments.interactive and arguments.fast:
        # Simulated time would rush through every prompt before a person could type.
        raise UsageError("--interactive: needs real or --speed time, not --fast")
    if arguments.view and (arguments.interactive or arguments.fast):
        # The view has the terminal; in simulated time it would only show the end.
        raise UsageError("--view: needs real or --speed time, without --interactive")
    if arguments.interactive and not stdin_readable():
        print(
            "error: --interactive: standard input is closed, and the children's keys are read "
            "from it: run the demo from a terminal",
            file=sys.stderr,
        )
        return 1
    teacher = Teacher(arguments.p_wrong_green, arguments.p_wrong_red, arguments.p_no_answer)
    if arguments.teacher is not None and teacher != Teacher():
        raise UsageError("--teacher: the model gives the rates; drop the --p-* options")
    config = load_config(arguments.config, playable=True) if arguments.config else demo_config()
    if arguments.language:
        config = with_language(config, arguments.language)
    if arguments.variant and arguments.variant != config.game.variant:
        config = with_variant(config, arguments.variant)
    think_s = DEFAULT_THINK_S
    if arguments.teacher is not None:
        model = load_teacher(arguments.teacher)
        teacher, think_s = model.pooled(), model.think_s()
    messiness = Messiness(arguments.p_hold, arguments.p_double, arguments.p_both, arguments.p_early)
    view = arguments.view and sys.stdout.isatty()
    if arguments.view and not view:
        print("note: --view: stdout is not a terminal, so the transcript", file=sys.stderr)
    # The dialogue is the demo's output; log lines go to stderr, warnings and worse only
    # (held back while the view has the screen, and printed after).
    held_logs = io.StringIO()
    configure_logging("warning", "console", stream=held_logs if view else sys.stderr)
    seed = arguments.seed if arguments.seed is not None else secrets.randbelow(2**31)
    state_dir = Path(arguments.state_dir or tempfile.mkdtemp(prefix="kaspar-demo-"))
    options = DemoOptions(
        state_dir=state_dir,
        seed=seed,
        teacher=teacher,
        think_s=think_s,
        messiness=messiness,
        p_unmoved_arm=arguments.p_unmoved_arm,
        interactive=arguments.interactive,
        uncertainty=arguments.uncertainty,
        motion=arguments.motion,
        voice=arguments.voice,
        interruptions=Interruptions(
            arguments.p_researcher_pause, arguments.p_researcher_undo, arguments.p_researcher_stop
        ),
        # A reader that goes away (`| head`) ends the demo, quietly (exit 0).
        out=cast(TextIO, Transcript(sys.stdout)),
    )
    lock = StateDirLock(state_dir)
    try:
        lock.acquire()
    except OSError as error:
        reason = error.strerror or str(error)
        print(f"error: {state_dir}: cannot use the state directory: {reason}", file=sys.stderr)
        return 1
    try:
        if view:
            result = _with_view(config, options, arguments.speed)
        else:
            result = run_demo(config, options, speed=arguments.speed, fast=arguments.fast)
    finally:
        lock.release()
        sys.stderr.write(held_logs.getvalue())
    print(
        f"\n{result.trials} guesses, {result.learned} toys learned, session {result.session} "
        f"{result.final_state} (seed {seed}). Records: {state_dir}"
    )
    if arguments.json:
        print(json.dumps(result.summary()))
    return 0


def _with_view(config: Config, options: DemoOptions, speed: float | None) -> DemoResult:
    """The demo drawn by the live view: the transcript goes nowhere, the records are the picture."""
    # Imported here: the daemon, which imports every command module, does not need them.
    from kasparctl.view.live import run_with_view
    from kasparctl.view.screen import open_keys, open_screen

    with open(os.devnull, "w", encoding="utf-8") as transcript:
        options.out = transcript
        keys = open_keys(sys.stdin)
        screen = open_screen(sys.stdout)
        try:
            return run_with_view(
                options.state_dir,
                lambda: run_demo(config, options, speed=speed),
                screen,
                keys,
                lambda result: f"the demo is {result.final_state}.",
            )
        finally:
            screen.close()
            if keys is not None:
                keys.close()
