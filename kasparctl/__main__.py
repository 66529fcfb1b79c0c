"""`python -m kasparctl`: the same command line as the `kasparctl` script."""

from kasparctl.cli import main

raise SystemExit(main())
