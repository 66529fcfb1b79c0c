"""Where the research commands read sessions from: --state-dir, or the config's state_dir.

Kept to two rules so a researcher can predict it: an explicit --state-dir
wins; otherwise the configuration (--config, else $KASPAR_CONFIG, else
/etc/kaspar/kaspar.toml) names it. A configuration given with --config is
also where learner profiles beyond the built-in ones are defined.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from kasparctl.config import Config, ConfigError, default_config_path, load_config
from kasparctl.learning.learner import LearnerParams
from kasparctl.research.catalogue import (
    CatalogueError,
    SessionData,
    find_sessions,
    load_session,
)
from kasparctl.research.progress import progress


class SourceError(Exception):
    """No usable state directory or configuration; the message says what to give."""


def add_source_arguments(parser: argparse.ArgumentParser, sessions: bool = True) -> None:
    """Add SESSION..., --state-dir and --config to a research command's parser."""
    if sessions:
        parser.add_argument(
            "sessions",
            nargs="*",
            metavar="SESSION",
            help="session ids or session directories (default: every session)",
        )
    parser.add_argument(
        "--state-dir", default=None, help="the robot's state directory (default: the config's)"
    )
    parser.add_argument(
        "--config",
        default=None,
        help="kaspar.toml whose state_dir and learner profiles to use "
        "(default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )


@dataclass(frozen=True)
class Source:
    """Where the sessions are, and the configuration whose learner profiles apply."""

    state_dir: Path | None
    config: Config | None

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
    if arguments.state_dir is not None:
        state_dir = Path(arguments.state_dir)
    elif not needs_state_dir:
        return Source(None, config)
    else:
        if config is None:
            path = default_config_path()
            if not Path(path).is_file():
                raise SourceError(
                    f"no state directory: give --state-dir DIR, or --config FILE "
                    f"(the default configuration {path} does not exist)"
                )
            config = _load(path)
        state_dir = Path(config.state_dir)
    if not state_dir.is_dir():
        raise SourceError(f"{state_dir}: no such state directory")
    return Source(state_dir, config)


def _load(path: str) -> Config:
    try:
        return load_config(path)
    except ConfigError as error:
        raise SourceError(str(error)) from error


def read_sessions(arguments: argparse.Namespace) -> tuple[Source, list[SessionData]]:
    """The sessions the command names (all by default), each record warning on stderr."""
    names = list(getattr(arguments, "sessions", None) or ())
    # Sessions named by their directory need no state directory at all.
    paths_only = bool(names) and all(Path(name).is_dir() for name in names)
    source = resolve_source(arguments, needs_state_dir=not paths_only)
    try:
        directories = find_sessions(source.state_dir, names)
        sessions = [
            load_session(directory)
            for directory in progress(directories, "reading sessions", "session")
        ]
    except CatalogueError as error:
        raise SourceError(str(error)) from error
    for session in sessions:
        for warning in session.warnings:
            # Never silently dropped: a damaged line is data a researcher may be missing.
            print(f"warning: {warning}", file=sys.stderr)
    return source, sessions
