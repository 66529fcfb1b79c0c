"""The service on the robot: the daemon and its talk with systemd (sd_notify)."""
