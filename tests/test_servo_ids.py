"""Servo ids: `servos scan` covers every id a protocol allows; `servos set-id` renames one.

Through the strict HerkuleX emulator over a pty: Kaspar 3's 16 servos (1-6, 16-20,
32-36) and a factory-new one at 253 are all found by a scan with no --ids; set-id
writes EEP 6, reads it back, reboots the servo and scans again, and refuses an id
that a servo on the bus already has.
"""

from __future__ import annotations

import json

import pytest
from emulators.herkulex import FACTORY_ID, HerkulexEmulator

from hal.servos import dynamixel1 as dx1
from hal.servos import dynamixel2 as dx2
from hal.servos import herkulex as hx
from hal.servos import maestro as mo
from kasparctl.bringup.servos import DEFAULT_IDS
from kasparctl.cli import main

KASPAR_3 = [*range(1, 7), *range(16, 21), *range(32, 37)]


def test_the_default_ids_are_each_protocols_own_range():
    assert DEFAULT_IDS == {
        "dynamixel1": dx1.ID_RANGE, "dynamixel2": dx2.ID_RANGE,
        "herkulex": hx.ID_RANGE, "maestro": mo.ID_RANGE,
    }
    assert DEFAULT_IDS["herkulex"] == (0, 253) and hx.FACTORY_ID == FACTORY_ID == 253
    assert DEFAULT_IDS["maestro"] == (0, 23)


def _scan(port, capsys, *extra):
    code = main(["servos", "scan", "--port", str(port), "--protocol", "herkulex",
                 "--baud", "115200", "--json", *extra])
    return code, json.loads(capsys.readouterr().out)


@pytest.mark.slow
def test_a_default_scan_finds_kaspar_3s_servos_and_a_factory_new_one(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[*KASPAR_3, FACTORY_ID]) as emulator:
        code, found = _scan(emulator.path, capsys)
        stats = {p[3] for p in emulator.received if p[4] == hx.Command.STAT}
    assert code == 0
    assert [servo["id"] for servo in found] == [*KASPAR_3, 253]
    assert all(servo["model"] == "drs-0101" for servo in found)
    assert stats == set(range(254))  # every id asked, in a STAT


@pytest.mark.slow
def test_set_id_renames_a_factory_new_servo_and_scans_again(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2, FACTORY_ID]) as emulator:
        code = main(["servos", "set-id", "--port", str(emulator.path), "--new-id", "16"])
        out = capsys.readouterr().out
        assert code == 0
        assert sorted(emulator.servos) == [1, 2, 16]
        assert emulator.servos[16].eep[hx.Eep.ID] == 16
        kinds = [p[4] for p in emulator.received if p[3] == FACTORY_ID]
        # EEP write of the id, its read back, then the reboot, in that order.
        eep_write = kinds.index(hx.Command.EEP_WRITE)
        assert kinds.index(hx.Command.REBOOT) > eep_write
        assert hx.Command.EEP_READ in kinds[eep_write:]
        code, found = _scan(emulator.path, capsys, "--ids", "1-20,253")
    lines = out.splitlines()
    assert lines[0] == "id 253 -> 16: EEP 6 written and read back (16), servo rebooted; on the bus now:"
    assert [line.split()[1] for line in lines[1:]] == ["1", "2", "16"]
    assert [servo["id"] for servo in found] == [1, 2, 16]


@pytest.mark.slow
def test_set_id_refuses_an_id_already_on_the_bus_naming_what_it_found(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[16, FACTORY_ID]) as emulator:
        code = main(["servos", "set-id", "--port", str(emulator.path), "--new-id", "16"])
        written = [p for p in emulator.received if p[4] == hx.Command.EEP_WRITE]
        assert sorted(emulator.servos) == [16, FACTORY_ID]
    err = capsys.readouterr().err
    assert code == 1 and not written
    assert "id 16 is already on the bus (drs-0101 at position 528)" in err
    assert "found: 16 (drs-0101), 253 (drs-0101)" in err


@pytest.mark.slow
def test_set_id_names_the_bus_when_nothing_answers_at_the_id(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[3]) as emulator:
        code = main(["servos", "set-id", "--port", str(emulator.path), "--new-id", "16"])
    err = capsys.readouterr().err
    assert code == 1 and "no servo answers at id 253" in err and "found: 3 (drs-0101)" in err


def test_a_scan_asks_again_the_servos_whose_replies_came_late(tmp_path, capsys):
    # A busy machine or a slow adapter: every reply comes after the scan's 10 ms margin,
    # so it lands in the next id's exchange; those ids are asked again, more patiently.
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[2, 3, 9]) as emulator:
        emulator.reply_delay = 0.015
        code, found = _scan(emulator.path, capsys, "--ids", "0-14")
    assert code == 0 and [servo["id"] for servo in found] == [2, 3, 9]
