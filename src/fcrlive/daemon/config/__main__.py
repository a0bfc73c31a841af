"""``python -m fcrlive.daemon.config [docs/config.md]``: regenerate the configuration docs."""

import sys

from fcrlive.daemon.config.docs import main

sys.exit(main())
