from nlosplan.cli import main

raise SystemExit(main())
