"""One robot's own centres: a small file of `[joint] centre_raw = N` merged over [servos].

The published Kaspar 3 definition is one robot.xml and a child file per robot
(kaspar3-1.xml .. kaspar3-10.xml) giving that robot's eye centres and, for two of
them, its torso's. The profile names its robot's file as `centres_file`:

    # Kaspar 3 no. 8 (kaspar3-8.xml)
    [right_eyelid]
    centre_raw = 5240   # EYE_R_LID CENTER 1310 us

Strict: a table must name a real joint of the profile and hold only centre_raw, a
whole number the joint's servo can take; every error names the file and the key.
The ranges stay relative to the centre, as the published limits were.
"""

from __future__ import annotations

from pathlib import Path

import msgspec

from hal.errors import SettingsError
from kasparctl.config.errors import ConfigError, read_toml
from kasparctl.config.schema import Config

KEYS = ("centre_raw",)


def read_centres(path: str | Path, joints: tuple[str, ...]) -> dict[str, int]:
    """Joint -> centre_raw from a centres file; ConfigError names the file and key at fault."""
    source = str(path)
    raw = read_toml(path)
    centres: dict[str, int] = {}
    for joint, table in raw.items():
        if joint not in joints:
            raise ConfigError(source, joint, f"expected a joint of the profile "
                              f"({', '.join(joints) or 'none configured'}), found {joint!r}")
        if not isinstance(table, dict):
            raise ConfigError(source, joint, f"expected a [{joint}] table with centre_raw, "
                              f"found {table!r}")
        for key, value in table.items():
            if key not in KEYS:
                raise ConfigError(source, f"{joint}.{key}",
                                  f"expected one of {', '.join(KEYS)}, found an unknown key")
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(source, f"{joint}.{key}",
                                  f"expected a whole number of the servo's raw units, "
                                  f"found {value!r}")
            centres[joint] = value
    return centres


def apply_centres_file(config: Config) -> Config:
    """The configuration with its centres_file's centres on the joints it names."""
    assert config.centres_file is not None
    source = config.centres_file
    servos = config.servos
    centres = read_centres(source, tuple(joint.name for joint in servos.joints))
    joints = []
    for joint in servos.joints:
        if joint.name in centres:
            try:
                joint = msgspec.structs.replace(joint, centre_raw=centres[joint.name])
            except SettingsError as error:
                raise ConfigError(source, f"{joint.name}.centre_raw", str(error)) from None
        joints.append(joint)
    return msgspec.structs.replace(
        config, servos=msgspec.structs.replace(servos, joints=tuple(joints))
    )
