"""Hardware abstraction: the robot's servos, keyfob and voice, each with a simulated twin.

The game sees only the interfaces defined here; drivers live in their own
modules and are chosen by the configuration. The HAL knows nothing of the game.
"""
