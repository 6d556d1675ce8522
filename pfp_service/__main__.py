import sys

from pfp_service.cli import main

sys.exit(main())
