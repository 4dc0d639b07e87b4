from serpar.cli import main

raise SystemExit(main())
