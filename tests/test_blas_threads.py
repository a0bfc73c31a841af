"""The BLAS thread count the process starts with must not change a number (fcrlive.blas).

With two OpenBLAS threads the simulator's cached discretisation (sim.model.build) came out different
in the 16th digit, and on the zoo's Kd = 0 unit B that moved max|S| by up to 3.7 % (docs/zoo.md)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np  # noqa: F401  (numpy's and SciPy's OpenBLAS loaded before threadpoolctl looks)
import scipy.linalg  # noqa: F401
from threadpoolctl import threadpool_info, threadpool_limits

from fcrlive.blas import one_thread, single_threaded

# The truth first (it builds and caches the plant's matrices, as the zoo benchmark does), then a record
# through a logger: every array of the logged signals hashed.
_SCRIPT = """
import hashlib, numpy as np
from fcrlive.sim import logger as lg, zoo
zoo.truth("B-int-beuler-10Hz")
res = zoo.simulate("B-int-beuler-10Hz", minutes=2, excitation=True, seed=2)
sig = lg.signals(res, zoo.zoo_logger("ctl-ideal"), seed=zoo.logger_seed(2, "ctl-ideal"))
h = hashlib.sha1()
for k in sorted(vars(sig)):
    v = getattr(sig, k)
    if isinstance(v, np.ndarray):
        h.update(np.ascontiguousarray(v).tobytes())
print(h.hexdigest())
"""


def _blas_threads() -> set[int]:
    return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}


def test_one_thread_limits_and_restores():
    with threadpool_limits(2, user_api="blas"):
        assert _blas_threads() == {2}
        with one_thread():
            assert _blas_threads() == {1}
        assert _blas_threads() == {2}

        @single_threaded
        def inside() -> set[int]:
            return _blas_threads()

        assert inside() == {1}
        assert _blas_threads() == {2}


def test_simulated_log_is_the_same_with_one_or_two_blas_threads():
    digests = []
    for n in ("1", "2"):
        env = dict(os.environ, OPENBLAS_NUM_THREADS=n, OMP_NUM_THREADS=n)
        out = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True,
                             timeout=240, check=True)
        digests.append(out.stdout.strip())
    assert len(digests[0]) == 40
    assert digests[0] == digests[1]

