"""Where the research commands read sessions from: --state-dir, or the config's state_dir.

Kept to two rules so a researcher can predict it: explicit --state-dir options
win (several pool robots or days into one study); otherwise the configuration
(--config, else $KASPAR_CONFIG, else /etc/kaspar/kaspar.toml) names it. A
configuration given with --config is also where learner profiles beyond the
built-in ones are defined. (kasparctl.commands.arguments.add_sources adds these
options to a command.)
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from hal.errors import KasparError
from kasparctl.config import Config, ConfigError, default_config_path, load_config
from kasparctl.learning.learner import LearnerParams
from kasparctl.research.catalogue import (
    Catalogue,
    CatalogueError,
    SessionData,
    find_sessions,
    open_sessions,
)
from kasparctl.research.participants import Participants
from kasparctl.research.progress import progress


class SourceError(KasparError):
    """No usable state directory or configuration; the message says what to give."""


@dataclass(frozen=True)
class Source:
    """Where the sessions are, and the configuration whose learner profiles apply."""

    state_dirs: tuple[Path, ...]
    config: Config | None

    @property
    def state_dir(self) -> Path | None:
        """The first state directory, if any (for messages)."""
        return self.state_dirs[0] if self.state_dirs else None

    def params(self, profile: str) -> LearnerParams:
        """A profile's learner parameters: the config's, else the built-in ones."""
        config = self.config or Config()
        try:
            return config.profile(profile)
        except KeyError:
            raise SourceError(
                f"unknown learner profile {profile!r}: give --config with the kaspar.toml "
                "that defines it"
            ) from None


def resolve_source(arguments: argparse.Namespace, needs_state_dir: bool = True) -> Source:
    """The source the arguments name, by the module's two rules; SourceError if there is none."""
    config = None
    if arguments.config is not None:
        config = _load(arguments.config)
    if arguments.state_dir:
        state_dirs = [Path(d) for d in arguments.state_dir]
    elif not needs_state_dir:
        return Source((), config)
    else:
        if config is None:
            path = default_config_path()
            if not Path(path).is_file():
                raise SourceError(
                    f"no state directory: give --state-dir DIR, or --config FILE "
                    f"(the default configuration {path} does not exist)"
                )
            config = _load(path)
        state_dirs = [Path(config.state_dir)]
    for state_dir in state_dirs:
        try:
            if not state_dir.is_dir():
                raise SourceError(f"{state_dir}: no such state directory")
        except PermissionError:
            raise SourceError(f"{state_dir}: permission denied") from None
    # The same directory twice is one source, not two copies of every session.
    unique = list(dict.fromkeys(state_dirs))
    return Source(tuple(unique), config)


def _load(path: str) -> Config:
    try:
        return load_config(path)
    except ConfigError as error:
        raise SourceError(str(error)) from error


def read_sessions(
    arguments: argparse.Namespace, report_damaged: bool = True
) -> tuple[Source, Catalogue]:
    """The sessions the command names (all by default); every warning and damage on stderr.

    A session that cannot be read is reported (one line: which file, and why;
    `report_damaged` False for a command that lists it itself) and left out; the
    command goes on with every other one.
    """
    names = list(getattr(arguments, "sessions", None) or ())
    # Sessions named by their directory need no state directory at all.
    paths_only = bool(names) and all(Path(name).is_dir() for name in names)
    source = resolve_source(arguments, needs_state_dir=not paths_only)
    try:
        directories = find_sessions(source.state_dirs, names)
    except CatalogueError as error:
        raise SourceError(str(error)) from error
    catalogue = open_sessions(progress(directories, "reading sessions", "session"))
    wanted = getattr(arguments, "condition", None)
    if wanted is not None:
        conditions = sorted({s.condition for s in catalogue.sessions})
        if wanted not in conditions:
            raise SourceError(
                f"--condition: expected one of {', '.join(conditions) or 'none (no sessions)'}, "
                f"found {wanted!r}"
            )
        catalogue.sessions = [s for s in catalogue.sessions if s.condition == wanted]
    for session in catalogue.sessions:
        for warning in session.warnings:
            # Never silently dropped: a damaged line is data a researcher may be missing.
            print(f"warning: {warning}", file=sys.stderr)
    for damaged in catalogue.damaged if report_damaged else ():
        print(f"warning: session left out, damaged: {damaged.reason}", file=sys.stderr)
    for duplicate in catalogue.duplicates:
        print(f"warning: {duplicate}", file=sys.stderr)
    return source, catalogue


def input_files(arguments: argparse.Namespace) -> list[tuple[str, str]]:
    """The files a command reads besides the sessions: no output may replace them."""
    files = []
    for option in ("config", "participants"):
        path = getattr(arguments, option, None)
        if path is not None:
            files.append((f"--{option}", str(path)))
    return files


def report_unknown_codes(sessions: Sequence[SessionData], participants: Participants) -> None:
    """Warn (stderr) about participant codes in the plans that participants.csv lacks."""
    if participants.path is None:
        return
    unknown = sorted(
        {code for s in sessions for code in s.participants if code not in participants.rows}
    )
    if unknown:
        print(
            f"warning: {participants.path}: no row for {', '.join(unknown)} (in the sessions' "
            "plans): their attribute columns are empty",
            file=sys.stderr,
        )
