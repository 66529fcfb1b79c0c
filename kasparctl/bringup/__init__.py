"""The engineer's tools at the robot: readiness, servos, calibration, poses and behaviours.

Bring-up opens the configured servos (real or simulated), voice and keyfob
itself, so it is an assembler (docs/architecture.md); the commands of
kasparctl.commands only parse their options and call it.
"""
