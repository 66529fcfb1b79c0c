"""The serial ports: what sysfs says each is, Kaspar 3's two Maestros told apart, the udev rules.

A fake sysfs tree holds what the kernel shows for Kaspar 3's two Mini Maestro 18s
(1ffb:008b, cdc_acm: interface 00 the Command Port, 02 the TTL Port) and an FTDI
adapter; the boards' Command Ports are Maestro emulators on ptys whose channel 17
reads as the published portNamer.py expects (head high, body low), and the body
board's TTL Port is a HerkuleX emulator: the helper must never write to it.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from emulators.herkulex import HerkulexEmulator
from emulators.maestro import MaestroEmulator

from hal.servos.ports import describe
from kasparctl.bringup.ports import PortNameError, port_names
from kasparctl.cli import main

REPO = Path(__file__).resolve().parents[1]
MAESTRO_PRODUCT = "Pololu Mini Maestro 18-Channel USB Servo Controller"


def _write(directory: Path, **files: str) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (directory / name).write_text(text + "\n")
    return directory


def _tty(sysfs: Path, parent: Path, name: str, under_tty_dir: bool = True) -> None:
    """A tty as the kernel shows it: /sys/class/tty/<name> -> its dir, with `device` -> parent."""
    tty = parent / "tty" / name if under_tty_dir else parent / name / "tty" / name
    tty.mkdir(parents=True)
    (tty / "device").symlink_to(parent if under_tty_dir else parent / name)
    (sysfs / "class" / "tty").mkdir(parents=True, exist_ok=True)
    (sysfs / "class" / "tty" / name).symlink_to(tty)


def _maestro(sysfs: Path, port: str, serial: str, first_tty: int) -> Path:
    usb = _write(sysfs / "devices/pci0000:00/0000:00:14.0/usb1" / port, idVendor="1ffb",
                 idProduct="008b", product=MAESTRO_PRODUCT, serial=serial,
                 manufacturer="Pololu Corporation")
    drivers = sysfs / "bus/usb/drivers/cdc_acm"
    drivers.mkdir(parents=True, exist_ok=True)
    for number, tty in (("00", first_tty), ("02", first_tty + 1)):
        interface = _write(usb / f"{port}:1.{int(number)}", bInterfaceNumber=number)
        (interface / "driver").symlink_to(drivers)
        _tty(sysfs, interface, f"ttyACM{tty}")
        data = int(number) + 1  # the CDC data interface beside each control interface
        _write(usb / f"{port}:1.{data}", bInterfaceNumber=f"{data:02d}")
    return usb


@pytest.fixture
def robot(tmp_path):
    """Kaspar 3's USB: head board ttyACM0/1, body board ttyACM2/3, an FTDI on ttyUSB0."""
    sysfs, dev = tmp_path / "sys", tmp_path / "dev"
    dev.mkdir()
    _maestro(sysfs, "1-1.2", "00201234", 0)
    _maestro(sysfs, "1-1.3", "00205678", 2)
    ftdi = _write(sysfs / "devices/pci0000:00/0000:00:14.0/usb1/1-1.4", idVendor="0403",
                  idProduct="6001", product="FT232R USB UART", serial="A9XYZ123")
    interface = _write(ftdi / "1-1.4:1.0", bInterfaceNumber="00")
    (sysfs / "bus/usb/drivers/ftdi_sio").mkdir(parents=True)
    (interface / "driver").symlink_to(sysfs / "bus/usb/drivers/ftdi_sio")
    _tty(sysfs, interface, "ttyUSB0", under_tty_dir=False)
    head = MaestroEmulator(tmp_path / "head-command", channels=18, inputs={17: 1023})
    body = MaestroEmulator(tmp_path / "body-command", channels=18, inputs={17: 0})
    herkulex = HerkulexEmulator(tmp_path / "body-ttl", ids=[1])
    for name, target in (("ttyACM0", head.path), ("ttyACM2", body.path),
                         ("ttyACM3", herkulex.path)):
        (dev / name).symlink_to(target)
    (dev / "ttyACM1").write_text("")  # the head board's TTL Port: nothing on it
    (dev / "ttyUSB0").write_text("")
    yield sysfs, dev, tmp_path / "lock", (head, body, herkulex)
    for emulator in (head, body, herkulex):
        emulator.stop()


def test_sysfs_names_the_adapter_its_interface_serial_and_driver(robot, tmp_path):
    sysfs, dev, _, _ = robot
    (dev / "kaspar-body").symlink_to(dev / "ttyUSB0")
    info = describe(str(dev / "kaspar-body"), sysfs)
    assert (info.vendor, info.product, info.interface, info.driver, info.serial) == (
        "0403", "6001", "00", "ftdi_sio", "A9XYZ123")
    assert str(info) == (f"{dev}/kaspar-body is {dev}/ttyUSB0: FTDI FT232R (USB2Dynamixel and "
                         "most USB-TTL cables) (0403:6001) interface 00, serial A9XYZ123, "
                         "driver ftdi_sio")
    (dev / "ttyACM1").unlink()
    (dev / "ttyACM1").write_text("")
    ttl = describe(str(dev / "ttyACM1"), sysfs)
    assert str(ttl).endswith("Pololu Mini Maestro 18 (1ffb:008b) interface 02 (TTL Port), "
                             "serial 00201234, driver cdc_acm")
    assert str(describe(str(dev / "nothing"), sysfs)) == f"{dev}/nothing: no such device"


def test_the_two_maestros_are_told_apart_by_channel_17_and_their_ttl_port_is_left_alone(robot):
    sysfs, dev, locks, (head, body, herkulex) = robot
    names = {tty: port_names(tty, sysfs, dev, locks) for tty in
             ("ttyACM0", "ttyACM1", "ttyACM2", "ttyACM3")}
    assert names == {
        "ttyACM0": ("kaspar-eyes", "kaspar-head-sensors"),
        "ttyACM1": ("kaspar-head-ttl",),
        "ttyACM2": ("kaspar-body-sensors",),
        "ttyACM3": ("kaspar-body",),  # the HerkuleX bus
    }
    # Each board's Command Port was asked for channel 17: Get Position, 0x90 17.
    assert all(packet == bytes((0x90, 17)) for packet in head.received + body.received)
    assert len(head.received) == 2 and len(body.received) == 2
    assert herkulex.received == []  # nothing written into the servo bus


def test_a_port_that_is_no_maestros_is_refused_by_name(robot, capsys):
    sysfs, dev, locks, _ = robot
    with pytest.raises(PortNameError, match="ttyUSB0 is not a Maestro's Command or TTL Port"):
        port_names("ttyUSB0", sysfs, dev, locks)
    code = main(["port-name", "ttyUSB0", "--sysfs", str(sysfs), "--dev", str(dev),
                 "--lock-dir", str(locks)])
    captured = capsys.readouterr()
    assert code == 1 and captured.out == "" and "ttyUSB0 is not a Maestro" in captured.err
    code = main(["port-name", "ttyACM3", "--sysfs", str(sysfs), "--dev", str(dev),
                 "--lock-dir", str(locks)])
    assert code == 0 and capsys.readouterr().out == "kaspar-body\n"  # udev's %c, alone


def test_check_names_the_device_behind_each_bus(tmp_path, capsys):
    from test_servo_cli import herkulex_config

    with HerkulexEmulator(tmp_path / "ttyHX", ids=[2, 6], models={6: "drs-0201"}) as emulator:
        main(["check", "--config", herkulex_config(tmp_path, emulator.path)])
    out = capsys.readouterr().out
    (row,) = [line for line in out.splitlines() if line.startswith("ports")]
    assert f"bus body: {emulator.path} is /dev/pts/" in row
    assert "not a USB adapter (no sysfs USB device: a pseudo-terminal or a UART)" in row


# --- the rules file, parsed as udev reads it ---------------------------------------------

MATCH = {"ACTION", "SUBSYSTEM", "SUBSYSTEMS", "DRIVERS", "KERNEL", "ATTRS", "ENV", "ATTR"}
ASSIGN = {"SYMLINK", "GROUP", "MODE", "ATTR", "PROGRAM", "RUN", "ENV"}
PAIR = re.compile(r'\s*([A-Z_]+)(?:\{([^}]+)\})?\s*(==|!=|\+=|-=|:=|=)\s*"([^"]*)"\s*(?:,|$)')


def _rules(text: str) -> list[list[tuple[str, str | None, str, str]]]:
    rules = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        pairs, at = [], 0
        while at < len(line):
            found = PAIR.match(line, at)
            assert found, f"line {number}: not udev syntax at {line[at:]!r}"
            pairs.append(found.groups())
            at = found.end()
        rules.append(pairs)
    return rules


def test_the_serial_rules_are_udev_syntax_and_name_kaspar_3s_ports():
    rules = _rules((REPO / "systemd/99-kaspar-serial.rules").read_text())
    for pairs in rules:
        for key, _attr, op, _value in pairs:
            known = MATCH if op in ("==", "!=") else ASSIGN
            assert key in known, f"{key}{op} is not a udev key for that operator"
    maestro = [p for p in rules if ("ATTRS", "idVendor", "==", "1ffb") in p]
    (helper,) = maestro
    assert ("ATTRS", "idProduct", "==", "008b") in helper
    assert ("ENV", "ID_USB_INTERFACE_NUM", "==", "00|02") in helper
    assert ("PROGRAM", None, "=", "/opt/kasparctl/bin/kasparctl port-name %k") in helper
    assert ("SYMLINK", None, "+=", "%c") in helper
    latency = [p for p in rules if any(k == "ATTR" and a == "latency_timer" for k, a, _, _ in p)]
    (only,) = latency  # the latency timer is an FTDI's only
    assert ("DRIVERS", None, "==", "ftdi_sio") in only
    vendors = {v for p in rules for k, a, _, v in p if (k, a) == ("ATTRS", "idVendor")}
    assert vendors == {"1ffb", "0403", "10c4", "1a86"}  # Maestro, FTDI, CP210x, CH340


def test_install_sh_installs_the_serial_rules():
    script = (REPO / "systemd/install.sh").read_text()
    assert "RULES=(99-kaspar-serial.rules 99-kaspar-keyfob.rules 99-kaspar-researcher.rules)" in script
    assert 'run install -D -m 0644 "$HERE/$rule" "$RULES_DIR/$rule"' in script
