"""The real processes on a real full disk: `kasparctl run` and `kasparctl demo` on a tmpfs.

The service (as systemd starts it: NOTIFY_SOCKET, simulated hardware, keys on stdin) and
the demo keep their records on a tmpfs of 256 KiB that the test fills to the last byte
mid-session. The service stays up (no traceback, no crash, no loop), shows and says that
it cannot save, and resumes once the space is back; the demo ends with one line and exit
1, and resumes from what it kept when run again. On the code before this work the demo
hung in its fault stage (its researcher's resume refused for ever).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from edge_fixtures import fill, root, small_tmpfs  # noqa: F401  (root: a fixture)
from service_fixtures import (
    DEMO_CONFIG,
    PHRASES,
    run_command,
    running_service,
    spoken,
    wait_for_record,
)

from kasparctl.game.session import RECORDS_FILE

POLL_S = 0.05  # how often the records are counted while waiting for the demo's trials


def trials_on_disk(state_dir: Path) -> list[int]:
    found = []
    for path in sorted((state_dir / "sessions").glob(f"*/{RECORDS_FILE}")):
        for line in path.read_text().splitlines():
            if line.strip():
                record = json.loads(line)
                if record["kind"] == "trial":
                    found.append(record["trial"])
    return found


@pytest.mark.slow  # the service in real time: about 10 s
@pytest.mark.usefixtures("root")
def test_the_service_on_a_full_disk_stays_up_says_so_and_resumes_once_freed(
    tmp_path: Path,
) -> None:
    config = tmp_path / "kaspar.toml"
    config.write_text(DEMO_CONFIG.read_text().replace('level = "warning"', 'level = "info"'))
    state_dir = tmp_path / "state"
    with small_tmpfs(state_dir), running_service(
        tmp_path, state_dir=state_dir, command=lambda s: run_command(s, config=config)
    ) as service:
        service.notify.wait_for("READY=1")
        service.press("G")  # long green: the session starts (placing)
        wait_for_record(state_dir, lambda r: r.get("to") == "placing")
        filler = fill(state_dir)
        mark = service.notify.mark()
        service.press("G")  # next: the step's record is refused
        status = service.notify.wait_for_status(lambda s: "CANNOT SAVE" in s, since=mark)
        assert "No space left on device" in status and "stop the session ('stop')" in status
        service.stderr.wait_for(lambda line: spoken(line, PHRASES["fault"]["storage"]))
        # Left alone it waits: no crash, no loop of games resumed.
        mark = service.notify.mark()
        service.notify.collect(3.0)
        assert service.process.poll() is None
        assert not any("READY=1" in m for _, m in service.notify.messages[mark:])
        filler.unlink()
        mark = service.notify.mark()
        service.press("R")  # long red: resumed once the disk takes the resume's record
        service.notify.wait_for_status(lambda s: s.startswith("step 2"), since=mark)
        assert service.stop() == 0
        output = service.stdout.text() + service.stderr.text()
        (log,) = (state_dir / "sessions").glob(f"*/{RECORDS_FILE}")
        records = [json.loads(line) for line in log.read_text().splitlines()]
    assert "Traceback" not in output
    assert [r["seq"] for r in records] == list(range(1, len(records) + 1))
    steps = [r["to"] for r in records if r["kind"] == "step"]
    assert steps == ["placing", "teaching"]  # teaching entered once, after the resume
    assert any(r["kind"] == "fault" and r["fault"] == "storage" for r in records)


def start_demo(state_dir: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "kasparctl", "demo", "--seed", "3", "--state-dir", str(state_dir),
         *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


@pytest.mark.slow  # the demo in real time at 50 times: about 8 s
@pytest.mark.usefixtures("root")
def test_the_demo_on_a_full_disk_ends_with_one_line_and_resumes_when_run_again(
    tmp_path: Path,
) -> None:
    state_dir = tmp_path / "state"
    with small_tmpfs(state_dir):
        demo = start_demo(state_dir, "--speed", "50")
        deadline = time.monotonic() + 60
        while len(trials_on_disk(state_dir)) < 2:
            assert demo.poll() is None and time.monotonic() < deadline
            time.sleep(POLL_S)
        filler = fill(state_dir)
        try:
            out, err = demo.communicate(timeout=60)
        finally:
            if demo.poll() is None:
                demo.kill()  # hung (as it did before this work): the test fails, no orphan
                demo.communicate()
        assert demo.returncode == 1
        last = err.strip().splitlines()[-1]
        assert last.startswith("error: the records cannot be saved: ")
        assert "No space left on device" in last and str(state_dir) in last
        assert "Traceback" not in err
        kept = trials_on_disk(state_dir)
        assert kept[:2] == [1, 2]
        filler.unlink()
        again = start_demo(state_dir, "--fast", "--json")
        out, err = again.communicate(timeout=60)
        assert again.returncode == 0, err
        summary = json.loads(out.strip().splitlines()[-1])
        assert summary["resumed"] and summary["finished"]
        trials = trials_on_disk(state_dir)
    assert trials[: len(kept)] == kept
    assert trials == sorted(set(trials)) and trials[0] == 1


def test_a_missing_servo_adapter_is_named_once_and_no_joint_is_said_to_the_children(
    tmp_path: Path,
) -> None:
    """The service on a robot whose servo adapter is not plugged in: STATUS= and the records
    name the bus and its device, the journal says it once, and Kaspar asks for a grown-up
    without naming a joint (before: "Ouch, my head yaw is not working")."""
    port = tmp_path / "kaspar-body"  # nothing there
    robot = DEMO_CONFIG.read_text().replace('backend = "sim"\nsafe_action', 'backend = "real"\nsafe_action')
    robot = robot.replace('port = "/dev/kaspar-body"', f'port = "{port}"')
    config = tmp_path / "kaspar.toml"
    config.write_text(robot + '\n[keyfob]\nbackend = "sim"\n\n[voice]\nbackend = "sim"\nrate = 450\n')
    adapter = f"bus body: cannot open {port}: no such device"

    def command(state_dir: Path) -> list[str]:
        return run_command(state_dir, config=config, sim=False)

    with running_service(tmp_path, command=command) as service:
        service.notify.wait_for("READY=1")
        status = service.notify.wait_for_status(lambda s: s.startswith("fault") and adapter in s)
        assert "servo fault" in status
        line = service.stderr.wait_for(lambda text: "Kaspar: " in text)
        assert spoken(line, PHRASES["fault"]["servo"]), line
        assert service.stop() == 0
        said = [text for text in service.stderr.text().splitlines() if "Kaspar: " in text]
    joints = ("head", "smile", "shoulder", "elbow", "yaw", "pitch", "joint")
    assert not any(word in text.split("Kaspar: ", 1)[1].lower() for text in said for word in joints)
    events = [json.loads(line) for line in (service.state_dir / "events.jsonl").read_text().splitlines()]
    faults = [r for r in events if r["kind"] == "fault" and r["fault"] == "servo"]
    assert faults and all(adapter in r["detail"] for r in faults)
