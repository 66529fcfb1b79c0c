"""The [keyfob] and [voice] tables of kaspar.toml: defaults, values and error messages."""

from __future__ import annotations

import pytest
from evdev import ecodes

from hal.keyfob.settings import DEFAULT_DEVICE, KeyfobSettings
from kasparctl.config import ConfigError, parse_config


def error_of(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "kaspar.toml")
    return str(caught.value)


def test_defaults_are_usable():
    config = parse_config("", "kaspar.toml")
    keyfob, voice = config.keyfob, config.voice
    assert (keyfob.long_press, keyfob.double_press, keyfob.bounce) == (1.0, 0.4, 0.03)
    assert keyfob.device_path == DEFAULT_DEVICE and keyfob.grab
    assert keyfob.key_map() == {ecodes.KEY_PAGEDOWN: "green", ecodes.KEY_PAGEUP: "red"}
    assert voice.engine == "espeak-ng" and voice.wav_dir is None


def test_a_full_configuration():
    config = parse_config(
        """
[keyfob]
name = "Kaspar keyfob"
grab = false
green = "KEY_VOLUMEUP"
red = 28
long_press = 1.5
[keyfob.commands]
KEY_P = "pause"
"30" = "undo"
[voice]
engine = "pyttsx3"
voice = "en-us"
rate = 140
volume = 0.8
timeout = 10.0
player = ["play", "-q"]
[voice.clips]
hello = "/usr/share/kaspar/hello.wav"
""",
        "kaspar.toml",
    )
    keyfob, voice = config.keyfob, config.voice
    assert keyfob.device_path is None and keyfob.name == "Kaspar keyfob"
    assert keyfob.key_map() == {
        ecodes.KEY_VOLUMEUP: "green",
        28: "red",
        ecodes.KEY_P: "pause",
        30: "undo",
    }
    assert (voice.engine, voice.voice, voice.rate, voice.volume) == ("pyttsx3", "en-us", 140, 0.8)
    assert voice.player == ("play", "-q")
    assert voice.clips == {"hello": "/usr/share/kaspar/hello.wav"}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[keyfob]\ncolour = 'green'", "kaspar.toml: keyfob.colour: unknown key; expected one of:"),
        ("[keyfob]\nbackend = 'usb'", "kaspar.toml: keyfob.backend: expected one of 'real', 'sim'"),
        ("[keyfob]\nlong_press = 'long'", "kaspar.toml: keyfob.long_press: expected float, found str"),
        (
            "[keyfob]\nlong_press = 0.3",
            "kaspar.toml: keyfob: expected bounce < double_press < long_press, found 0.03 / 0.4 / 0.3",
        ),
        ("[keyfob]\nbounce = -1.0", "kaspar.toml: keyfob.bounce: expected > 0 and <= 10 s, found -1.0"),
        (
            "[keyfob]\nreopen_grace = 61.0",
            "kaspar.toml: keyfob.reopen_grace: expected > 0 and <= 60 s, found 61.0",
        ),
        (
            "[keyfob]\ngreen = 'KEY_NOPE'",
            "kaspar.toml: keyfob: green: expected a key name known to evdev, found 'KEY_NOPE'",
        ),
        ("[keyfob]\nred = 'pageup'", "kaspar.toml: keyfob: red: expected a key name such as"),
        ("[keyfob]\nred = 'KEY_PAGEDOWN'", "kaspar.toml: keyfob: red uses the same key as green"),
        ("[keyfob]\ndevice = '/dev/x'\nname = 'x'", "kaspar.toml: keyfob: set device or name, not both"),
        (
            "[keyfob]\ndevice = 'event3'",
            "kaspar.toml: keyfob.device: expected an absolute device path, found 'event3'",
        ),
        ("[keyfob]\nname = ' '", "kaspar.toml: keyfob.name: expected a device name, found an empty string"),
        (
            "[keyfob.commands]\nKEY_P = 'Pause!'",
            "kaspar.toml: keyfob.commands.KEY_P: expected a name like 'pause', found 'Pause!'",
        ),
        (
            "[keyfob.commands]\nKEY_P = 'green'",
            "kaspar.toml: keyfob.commands.KEY_P: expected a name like 'pause', found 'green'",
        ),
        ("[keyfob.commands]\nKEY_NOPE = 'pause'", "kaspar.toml: keyfob: commands.KEY_NOPE: expected a key name known"),
        ("[voice]\nengine = 'festival'", "kaspar.toml: voice.engine: expected one of 'pyttsx3', 'espeak-ng'"),
        ("[voice]\nrate = 20", "kaspar.toml: voice.rate: expected 80 to 450 words per minute, found 20"),
        ("[voice]\nvolume = 1.5", "kaspar.toml: voice.volume: expected 0 to 1, found 1.5"),
        ("[voice]\ntimeout = 0.1", "kaspar.toml: voice.timeout: expected 1 to 300 s, found 0.1"),
        ("[voice]\nvoice = 'en gb'", "kaspar.toml: voice.voice: expected a voice name like 'en-gb', found 'en gb'"),
        # A pattern's $ would let a trailing newline through; the name is matched whole.
        (
            '[voice]\nvoice = "en-gb\\n"',
            "kaspar.toml: voice.voice: expected a voice name like 'en-gb', found 'en-gb\\n'",
        ),
        ("[voice]\nplayer = []", "kaspar.toml: voice: player: expected a command"),
        (
            "[voice.clips]\nhello = 'hello.wav'",
            "kaspar.toml: voice.clips.hello: expected an absolute .wav path, found 'hello.wav'",
        ),
        (
            "[voice.clips]\nhello = '/clips/hello.mp3'",
            "kaspar.toml: voice.clips.hello: expected an absolute .wav path, found '/clips/hello.mp3'",
        ),
        ("[voice.clips]\n'hel lo' = '/a.wav'", "kaspar.toml: voice: clips: expected a phrase key, found 'hel lo'"),
        ("[voice]\nspeed = 1", "kaspar.toml: voice.speed: unknown key; expected one of:"),
    ],
)
def test_errors_name_the_key(text, message):
    assert error_of(text).startswith(message)


def test_settings_are_frozen():
    with pytest.raises(AttributeError):
        KeyfobSettings().grab = False  # type: ignore[misc]
