"""`kasparctl check` on real parts: a keyfob found or named missing, the voice really speaking."""

from __future__ import annotations

from pathlib import Path

from kasparctl.cli import main


def config(tmp_path: Path, keyfob: str, voice: str) -> str:
    path = tmp_path / "kaspar.toml"
    # The pilot: nothing to teach, so no pointing arm is needed on the simulated servos.
    pilot = "[game]\nvariant = 'pilot'\nlocations = ['box']\n"
    path.write_text(f"{pilot}[servos]\nbackend = 'sim'\n[keyfob]\n{keyfob}\n[voice]\n{voice}\n")
    return str(path)


def test_voice_speaks_the_test_line_with_real_espeak_ng(tmp_path: Path, capsys) -> None:
    wavs = tmp_path / "wavs"
    wavs.mkdir()
    path = config(tmp_path, "backend = 'sim'", f"wav_dir = '{wavs}'")
    assert main(["check", "--config", path]) == 0
    assert "voice          ok    spoke the test line via espeak-ng" in capsys.readouterr().out
    (wav,) = wavs.glob("*.wav")
    assert wav.read_bytes()[:4] == b"RIFF" and wav.stat().st_size > 10_000


def test_missing_keyfob_is_named_and_fails(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "no-keyfob"
    path = config(tmp_path, f"device = '{missing}'", "backend = 'sim'")
    assert main(["check", "--config", path]) == 1
    out = capsys.readouterr().out
    assert f"keyfob         FAIL  cannot open {missing}: no such device" in out


def test_quiet_check_renders_the_voice_without_playing_it(tmp_path: Path, capsys) -> None:
    # No wav_dir: the real player (aplay) would be used, and --quiet must not need it.
    path = config(tmp_path, "backend = 'sim'", "player = ['/nonexistent/player']")
    assert main(["check", "--config", path, "--quiet"]) == 0
    assert "voice          ok    rendered the test line silently via espeak-ng" in capsys.readouterr().out
