from serpar.cli.entry import main

raise SystemExit(main())
