"""Kaspar's body language: behaviours as data, layers blended per joint, mouth, gaze, life.

Below the game, which drives it through `kasparctl.body.api.Body`, and above hal/servos,
which it moves (every command through the joints layer's clamps and speed limits).
"""
