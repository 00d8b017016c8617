"""Bad arguments to the public helpers of ``rsocl.testing`` (table of tests/test_bad_inputs.py)."""

import numpy as np

from rsocl.testing import dottest

from test_bad_inputs import Bad


class _Identity:
    domain_shape = range_shape = (2, 3)

    def forward(self, x):
        return x

    def adjoint(self, y):
        return y


CASES = [
    Bad("dottest-op-without-adjoint", ["op", "adjoint"], api=lambda tmp: dottest(np.eye(3))),
    Bad("dottest-domain-shape-zero", ["domain_shape", ">= 1"], api=lambda tmp: dottest(_Identity(), (0, 3))),
    Bad("dottest-no-range-shape", ["range_shape"], api=lambda tmp: dottest(_Identity(), (2, 3), ())),
    Bad("dottest-rtol-negative", ["rtol", "> 0"], api=lambda tmp: dottest(_Identity(), rtol=-1.0)),
]
