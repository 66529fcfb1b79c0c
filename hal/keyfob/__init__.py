"""The keyfob: the researcher's two buttons, as a stream of gestures.

The interface the game sees (api), settings, the evdev reader with hot-plug
(reader), the pure gesture recogniser (gestures) and the simulated twins (sim).
"""
