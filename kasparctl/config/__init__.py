"""kaspar.toml into typed, validated, frozen settings.

Every error names the file, the key path, what was expected and what was
found; unknown keys are rejected, so a misspelt key never silently falls back
to a default in front of children.

One module per job:

- schema    the tables as strict, frozen msgspec structs (Config, SessionPlan...),
            each key's own limits on its type;
- loading   the file's bytes to a Config: UTF-8, TOML, msgspec, then the rules
            (load_config, parse_config);
- explain   msgspec's validation errors in the file's words (key, expected, found);
- rules     the checks that span several keys or tables;
- session_settings  one session's settings: its plan, its profile and the robot-wide
            tables resolved (resolve_session), and read back from plan.json
            (recorded_session);
- poses     the poses file (read_poses, check_pose, apply_poses_file);
- errors    ConfigError, which all of them raise.

This package's face is every public name of the module it was: callers import
from kasparctl.config, never from its parts, which may be rearranged.
"""

from __future__ import annotations

from kasparctl.config.errors import ConfigError
from kasparctl.config.loading import (
    DEFAULT_CONFIG_PATH,
    default_config_path,
    load_config,
    parse_config,
    servo_backend_given,
)
from kasparctl.config.poses import (
    HAPPY_POSE,
    LISTENING_POSE,
    REST_POSE,
    SAD_POSE,
    apply_poses_file,
    check_pose,
    read_poses,
)
from kasparctl.config.rules import (
    GESTURES,
    GROUP_CODE_LIMIT,
    MAX_TRIALS_LIMIT,
    NAME_LIMIT,
    SEED_LIMIT,
    check_playable,
)
from kasparctl.config.schema import (
    BUILTIN_PROFILES,
    CODE_PATTERN,
    CONDITION_LABELS,
    MACHINE_ID_FILES,
    SPOKEN_MODES,
    UNCERTAINTY_MODES,
    BodySettings,
    Code,
    Config,
    DaemonSettings,
    ExcludeLearned,
    GameSettings,
    GazeSettings,
    LearnerSettings,
    LoggingSettings,
    Name,
    ProfileSettings,
    RobotSettings,
    Seconds,
    SessionPlan,
    UncertaintyMode,
    VoiceOverrides,
    default_robot_id,
)
from kasparctl.config.session_settings import (
    DEFAULT_ROBOT_NAME,
    SessionSettings,
    recorded_game,
    recorded_session,
    resolve_session,
)

__all__ = [
    "BUILTIN_PROFILES",
    "CODE_PATTERN",
    "CONDITION_LABELS",
    "DEFAULT_CONFIG_PATH",
    "DEFAULT_ROBOT_NAME",
    "GESTURES",
    "GROUP_CODE_LIMIT",
    "HAPPY_POSE",
    "LISTENING_POSE",
    "MACHINE_ID_FILES",
    "MAX_TRIALS_LIMIT",
    "NAME_LIMIT",
    "REST_POSE",
    "SAD_POSE",
    "SEED_LIMIT",
    "SPOKEN_MODES",
    "UNCERTAINTY_MODES",
    "BodySettings",
    "Code",
    "Config",
    "ConfigError",
    "DaemonSettings",
    "ExcludeLearned",
    "GameSettings",
    "GazeSettings",
    "LearnerSettings",
    "LoggingSettings",
    "Name",
    "ProfileSettings",
    "RobotSettings",
    "Seconds",
    "SessionPlan",
    "SessionSettings",
    "UncertaintyMode",
    "VoiceOverrides",
    "apply_poses_file",
    "check_playable",
    "check_pose",
    "default_config_path",
    "default_robot_id",
    "load_config",
    "parse_config",
    "read_poses",
    "recorded_game",
    "recorded_session",
    "resolve_session",
    "servo_backend_given",
]
