"""Bad command-line options and solver arguments (table of tests/test_bad_inputs.py)."""

import numpy as np

import rsocl

from test_bad_inputs import Bad


def _rig():
    return rsocl.Rig.paper_array(4, (8, 8), 0.18e-3, 35e-6)


def _reconstruct(**kw):
    rig = _rig()
    g = np.zeros((len(rig.cameras),) + tuple(rig.shape), np.float32)
    return lambda tmp: rsocl.reconstruct(g, rig, **kw)


def _tiled(**kw):
    from rsocl.scale import reconstruct_tiled

    rig = _rig()
    g = np.zeros((len(rig.cameras),) + tuple(rig.shape), np.float32)
    return lambda tmp: reconstruct_tiled(g, rig, tile=(4, 4), **kw)


CASES = [
    Bad("simulate-shape-zero", ["--shape"], argv=["simulate", "builtin", "--shape", "0", "8", "--out", "{tmp}/s.h5"]),
    Bad("simulate-cameras-zero", ["--cameras"], argv=["simulate", "builtin", "--cameras", "0", "--out", "{tmp}/s.h5"]),
    Bad("reconstruct-missing-capture", ["nothing.h5"], argv=["reconstruct", "{tmp}/nothing.h5", "--out", "{tmp}/r.h5"]),
    Bad("api-iterations-zero", ["iterations"], api=_reconstruct(iterations=0)),
    Bad("api-iterations-a-slip", ["iterations", "<= 1000000", "1000000000000"], api=_reconstruct(iterations=10**12)),
    Bad("api-tiled-iterations-a-slip", ["iterations", "<= 1000000"], api=_tiled(iterations=10**7)),
    Bad(
        "cli-iterations-a-slip",
        ["--iterations", "[1, 1000000]", "'1e12'"],
        argv=["demo", "--iterations", "1e12", "--out", "{tmp}/d"],
    ),
    Bad(
        "cli-iterations-two-signs",
        ["--iterations", "[1, 1000000]", "'+-5'"],
        argv=["demo", "--iterations", "+-5", "--out", "{tmp}/d"],
    ),
    Bad(
        "cli-plan-iterations-a-slip",
        ["--iterations", "<= 1000000"],
        argv=["plan", "--iterations", "2000000"],
    ),
    Bad("api-lam-negative", ["lam"], api=_reconstruct(lam=-1.0)),
    Bad("api-tv-fused-below-the-device-choice", ["fused", "-1"], api=_reconstruct(regularizer_options={"fused": -2})),
    Bad("api-tv-one-launch-above-two", ["one_launch", "2"], api=_reconstruct(regularizer_options={"one_launch": 3})),
    Bad("api-quality-unknown", ["quality", "fast, balanced, best", "'medium'"], api=_reconstruct(quality="medium")),
    Bad("api-iterations-not-auto", ["iterations", "'auto'", "'many'"], api=_reconstruct(iterations="many")),
    Bad(
        "api-iterations-auto-on-fast",
        ["iterations='auto'", "quality 'fast'"],
        api=_reconstruct(quality="fast", iterations="auto"),
    ),
    Bad("cli-quality-unknown", ["--quality", "medium"], argv=["demo", "--quality", "medium", "--out", "{tmp}/d"]),
    Bad(
        "cli-iterations-not-auto", ["--iterations", "'many'"], argv=["demo", "--iterations", "many", "--out", "{tmp}/d"]
    ),
    Bad(
        "cli-iterations-auto-on-fast",
        ["--iterations auto", "quality 'fast'"],
        argv=["demo", "--fast", "--iterations", "auto", "--out", "{tmp}/d"],
    ),
    Bad(
        "cli-fast-and-quality-best",
        ["--fast", "--quality best"],
        argv=["demo", "--fast", "--quality", "best", "--out", "{tmp}/d"],
    ),
    Bad("api-tiled-iterations-auto", ["iterations='auto'", "tiled"], api=_tiled(iterations="auto")),
]
