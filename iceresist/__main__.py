from iceresist.cli import main

raise SystemExit(main())
