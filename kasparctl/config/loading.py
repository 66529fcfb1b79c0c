"""Loading kaspar.toml: its bytes into typed, validated, frozen settings (Config).

UTF-8, then TOML, then msgspec into the schema (unknown keys rejected, a key's
own limits held), then the rules across tables; then the voice follows the
language, relative paths are anchored at the file and the poses file is read.
A `sessions_file` gives the planned sessions (kasparctl.config.sessions_file),
held to the same rules as sessions planned in kaspar.toml.
Every error names the file, the key path, what was expected and what was found.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any

import msgspec

from hal.voice.settings import voice_for_language
from kasparctl.config.centres import apply_centres_file
from kasparctl.config.errors import ConfigError, utf8_text
from kasparctl.config.explain import explain_validation_error
from kasparctl.config.poses import apply_poses_file
from kasparctl.config.rules import check_playable, validate
from kasparctl.config.schema import Config
from kasparctl.config.sessions_file import apply_sessions_file

DEFAULT_CONFIG_PATH = Path("/etc/kaspar/kaspar.toml")


def default_config_path() -> str:
    """The configuration to read when none is given: $KASPAR_CONFIG, else DEFAULT_CONFIG_PATH."""
    return os.environ.get("KASPAR_CONFIG", str(DEFAULT_CONFIG_PATH))


def load_config(path: str | Path, *, poses: bool = True, playable: bool = False) -> Config:
    """Read and validate a configuration file; ConfigError says what is wrong and where.

    `poses=False` leaves the poses file unread (the bring-up commands that write it
    read it themselves, pose by pose). `playable` also holds the rules of a robot the
    game is played on (check_playable): `check`, `run` and `demo` ask for them; the
    bring-up tools read a robot still being put together.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ConfigError(str(path), "(file)", f"cannot read it: {error.strerror}") from error
    config = parse_config(data, str(path), base_dir=path.parent, poses=poses)
    if playable:
        check_playable(config, str(path))
    return config


def parse_config(
    data: bytes | str, source: str, base_dir: Path | None = None, *, poses: bool = True
) -> Config:
    """Validate a configuration's text; `source` names it in errors, `base_dir` anchors paths.

    With `poses`, the poses file (if named) fills the game's poses and the rest
    positions; see apply_poses_file.
    """
    text = utf8_text(data, source) if isinstance(data, bytes) else data
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", f"not valid TOML: {error}") from error
    try:
        config = msgspec.convert(raw, type=Config)
    except msgspec.ValidationError as error:
        key, message = explain_validation_error(str(error), raw)
        raise ConfigError(source, key, message) from error
    config, sessions_source = apply_sessions_file(config, raw, source, base_dir)
    try:
        validate(config, source)
    except ConfigError as error:
        if sessions_source is None or not error.key.startswith("sessions["):
            raise
        # The session at fault is in the sessions file: name it, not kaspar.toml.
        raise ConfigError(sessions_source, error.key, error.message) from None
    if "voice" not in raw.get("voice", {}):
        # The voice follows the language unless the file names one.
        voice = msgspec.structs.replace(config.voice, voice=voice_for_language(config.language))
        config = msgspec.structs.replace(config, voice=voice)
    if base_dir is not None:
        config = _resolve_paths(config, base_dir)
    if config.centres_file is not None:
        config = apply_centres_file(config)
    if poses and config.poses_file is not None:
        config = apply_poses_file(config, source)
    return config


def servo_backend_given(path: str | Path) -> bool:
    """Whether the file says which servos it drives: a [servos] table with its `backend`.

    Without one the servos default to simulated ones, which on the robot would be a
    silent simulation: `kasparctl run` (without --sim) and `check` refuse it.
    """
    try:
        raw = tomllib.loads(Path(path).read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False  # load_config says what is wrong with the file itself
    servos = raw.get("servos")
    return isinstance(servos, dict) and "backend" in servos


def _resolve_paths(config: Config, base_dir: Path) -> Config:
    """Relative paths in a configuration are relative to the file, not to the cwd."""
    changes: dict[str, Any] = {"state_dir": str(base_dir / config.state_dir)}
    if config.phrases_dir is not None:
        changes["phrases_dir"] = str(base_dir / config.phrases_dir)
    if config.poses_file is not None:
        changes["poses_file"] = str(base_dir / config.poses_file)
    if config.centres_file is not None:
        changes["centres_file"] = str(base_dir / config.centres_file)
    return msgspec.structs.replace(config, **changes)
