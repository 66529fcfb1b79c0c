"""The boot test's harness: a Debian 12 booted with systemd as PID 1 in a container."""
