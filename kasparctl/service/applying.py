"""What a reload applies at once, and what waits for the service to start again.

A reload between sessions applies every key a game reads when it begins (the plan,
the game, the learner, the phrases, the language, the voice's engine, voice, rate,
volume and pitch, the robot's name). What was built or opened once at the start
cannot change under a running daemon: the servos and their buses, the keyfob, the
researcher's device, the body, the state directory, the logging, where the sound
goes. Those keep their running values, and each one the new file changes is named.
"""

from __future__ import annotations

from pathlib import Path

import msgspec

from kasparctl.config import Config

# Tables (and top-level keys) opened once at the start.
_RESTART_TABLES = ("servos", "keyfob", "researcher", "body", "logging", "centres_file")
# [voice] keys that choose where the sound goes (the mouth listens to that sink).
_RESTART_VOICE = ("backend", "player", "wav_dir", "espeak_ng")


def restart_only(running: Config, loaded: Config, state_dir: Path) -> tuple[Config, list[str]]:
    """`loaded` with the running values kept where they take a restart, and the keys
    (as kaspar.toml names them) whose new values wait for it."""
    kept: list[str] = []
    changes: dict[str, object] = {}
    for key in _RESTART_TABLES:
        if getattr(loaded, key) != getattr(running, key):
            kept.append(key)
            changes[key] = getattr(running, key)
    if Path(loaded.state_dir) != state_dir:
        kept.append("state_dir")
        changes["state_dir"] = running.state_dir
    voice = {}
    for key in _RESTART_VOICE:
        if getattr(loaded.voice, key) != getattr(running.voice, key):
            kept.append(f"voice.{key}")
            voice[key] = getattr(running.voice, key)
    if voice:
        changes["voice"] = msgspec.structs.replace(loaded.voice, **voice)
    return msgspec.structs.replace(loaded, **changes), kept
