"""No docstring or comment of the package, its plugins or its kernels reports a measurement (dB,
timings, speed-ups, GPU models, seeds of a campaign): those live in ``docs/`` pages, which the
code points to in one line.
"""

import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Numbers that look like measurements and are conventions: ``(file, match)``.
CONVENTIONS = {("rsocl/bench/plots.py", "99 dB")}  # where an exact (infinite) PSNR is drawn

#: What a measurement looks like in prose.
MEASUREMENT = re.compile(
    "|".join(
        [
            r"[-+]?\d+(\.\d+)? ?dB\b",  # a PSNR or a gain in dB
            # a timing
            r"\b(takes?|took|ran|runs|costs?|about)\s+(about\s+)?\d+(\.\d+)?(-\d+(\.\d+)?)? ?(ms|µs|us|s)\b",
            r"\d+(\.\d+)?(-\d+(\.\d+)?)?x (the|slower|faster)\b",  # a speed-up
            r"\d+(\.\d+)?(-\d+(\.\d+)?)? ?% (faster|slower|more|less|of the \w+ time)",
            r"\bH[12]00\b",  # a GPU's figures
            r"\bseeds? \d+",  # a campaign's seeds
        ]
    )
)


def _python_prose(text):
    """``(line, text)`` of every comment and docstring-like string of a Python source."""
    previous = None
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
        elif tok.type == tokenize.STRING and previous in (
            None,
            tokenize.NEWLINE,
            tokenize.INDENT,
            tokenize.DEDENT,
            tokenize.NL,
        ):
            yield tok.start[0], tok.string
        if tok.type not in (tokenize.COMMENT, tokenize.NL):
            previous = tok.type


def _c_prose(text):
    for match in re.finditer(r"/\*.*?\*/|//[^\n]*", text, re.S):
        yield text.count("\n", 0, match.start()) + 1, match.group()


def _sources():
    for folder, pattern in (("rsocl", "*.py"), ("plugins", "*.py"), ("kernels", "*.cl")):
        for path in sorted((ROOT / folder).rglob(pattern)):
            yield path.relative_to(ROOT).as_posix(), path


@pytest.mark.parametrize("rel", [rel for rel, _ in _sources()])
def test_no_measurement_in_docstrings_or_comments(rel):
    path = ROOT / rel
    text = path.read_text(encoding="utf-8")
    prose = _c_prose(text) if path.suffix == ".cl" else _python_prose(text)
    found = [
        f"{rel}:{line + chunk[: m.start()].count(chr(10))}: {m.group()!r}"
        for line, chunk in prose
        for m in MEASUREMENT.finditer(chunk)
        if (rel, m.group()) not in CONVENTIONS
    ]
    assert not found, f"measurements belong in a docs/ page (point to it in one line): {found}"


def test_the_pattern_finds_measurements():
    for text in (
        "gained +0.15 dB on average",
        "takes about 45-70 ms per call",
        "1.5-2x slower",
        "ran 7-15 % faster",
        "pay 15-35 % more",
        "on an NVIDIA H100",
        "seed 100: 7 cam",
        "costs about 10 µs",
    ):
        assert MEASUREMENT.search(text), text
    for text in ("PSNR in dB", "t_e = 180 µs", "exposure time, µs", "seed : int", "units of 100 µs"):
        assert not MEASUREMENT.search(text), text
