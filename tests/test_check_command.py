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


def test_the_body_behaviours_are_checked_against_the_robot(tmp_path: Path, capsys) -> None:
    demo = (Path(__file__).resolve().parent.parent / "kasparctl" / "sim" / "demo.toml").read_text()
    path = tmp_path / "kaspar.toml"
    sim = "\n[keyfob]\nbackend = 'sim'\n[voice]\nbackend = 'sim'\n"
    mine = tmp_path / "mine"
    mine.mkdir()

    def check(body: str) -> tuple[int, str]:
        path.write_text(demo.replace("[body]\nenabled = true\n", body) + sim)
        code = main(["check", "--config", str(path), "--quiet"])
        return code, capsys.readouterr().out

    code, out = check("[body]\nenabled = false\n")
    assert code == 0 and "body           ok    still ([body] enabled = false)" in out
    # The shipped behaviours on the demo's smaller robot: the joints it lacks are named.
    code, out = check("[body]\nenabled = true\n")
    assert code == 0
    assert ("body           ok    behaviours that fit this robot: 12 (joints it lacks, skipped "
            "when played: left_elbow, left_shoulder_roll)") in out
    # One that would be clamped, or is not a behaviour at all, fails, named.
    (mine / "x.toml").write_text("[far]\nkeyframes = [{ time = 5.0, pose = { head_yaw = 200.0 } }]\n")
    code, out = check(f"[body]\nenabled = true\nbehaviours_dir = '{mine}'\n")
    assert code == 1
    assert ("body           FAIL  " + str(mine / "x.toml") + ": behaviour 'far', keyframe 1 "
            "(at 5 s), joint head_yaw: would be clamped") in out
    (mine / "x.toml").write_text("[far]\nkeyframes = 'none'\n")
    code, out = check(f"[body]\nenabled = true\nbehaviours_dir = '{mine}'\n")
    assert code == 1 and "body           FAIL  " in out
