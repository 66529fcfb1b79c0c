from kasparctl.cli import main

raise SystemExit(main())
