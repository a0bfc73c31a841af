"""``python -m fcrlive.excitation --port PORT --register-map FILE``: the excitation driver of
:mod:`fcrlive.commands._excitation` (drive a governor's excitation until SIGTERM; tests/demos)."""

import sys

from fcrlive.commands._excitation import main

sys.exit(main())
