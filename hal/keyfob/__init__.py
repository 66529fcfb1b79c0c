"""The keyfob: the interface the game sees (api), settings, the evdev reader with hot-plug
(reader), the pure gesture recogniser (gestures) and the simulated twin (sim)."""
