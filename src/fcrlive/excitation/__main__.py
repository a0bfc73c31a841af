"""``python -m fcrlive.excitation --port PORT``: drive a governor's excitation until SIGTERM (tests/demos)."""

import sys

from fcrlive.excitation.task import main

sys.exit(main())
