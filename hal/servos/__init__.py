"""The servos: named joints in degrees over serial buses of smart servos.

The interface the game sees (api), settings, the joints layer that enforces
safety (joints), one owner thread per serial port (bus), a driver per protocol
family (drivers) over its packet codec (dynamixel1, dynamixel2, herkulex,
maestro), and the simulated twin (sim).
"""
