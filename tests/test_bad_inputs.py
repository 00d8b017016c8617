"""Bad inputs across the CLI and the API, as one table.

Every case must fail before any long work with **one line** that names the parameter at fault
(and its allowed range where it has one), and leave every file that was there before unchanged.

The table is gathered from the ``CASES`` lists of the modules ``tests/bad_inputs_*.py`` (one per
area: files, rigs, solver options, ...), so that each area keeps its cases next to each other.
A case is a :class:`Bad`:

- ``argv``: a CLI call, ``rsocl ARGV...``, run in-process in a fresh folder (the test's
  ``tmp_path``); ``{tmp}`` in an argument is replaced by that folder. It must exit with ``rc`` and
  write exactly one ``rsocl COMMAND: error: ...`` line to stderr, and no traceback.
- ``api``: a callable ``api(tmp_path)`` that must raise one of ``errors`` with a one-line message.
- ``setup``: an optional ``setup(tmp_path)`` that writes the files that exist before the call
  (captures, rig files, earlier results); their bytes are hashed before and compared after.
- ``names``: strings that the message must contain (case-insensitive), e.g. the option and the
  allowed range.
"""

from __future__ import annotations

import hashlib
import importlib.util
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pytest

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Bad:
    """One bad input: a CLI call (``argv``) or an API call (``api``) and what its message names."""

    id: str
    names: Sequence[str]
    argv: Sequence[str] | None = None
    api: Callable | None = None
    setup: Callable | None = None
    errors: tuple = (ValueError,)
    rc: int = 2

    def __post_init__(self):
        if (self.argv is None) == (self.api is None):
            raise TypeError(f"case {self.id!r}: give exactly one of argv and api")
        if not self.names:
            raise TypeError(f"case {self.id!r}: names must list what the message names")


def gather(folder: Path = HERE) -> list:
    """Every ``CASES`` entry of ``folder/bad_inputs_*.py``, ids checked unique."""
    cases, seen = [], {}
    for path in sorted(folder.glob("bad_inputs_*.py")):
        spec = importlib.util.spec_from_file_location(f"rsocl_tests_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        for case in module.CASES:
            if case.id in seen:
                raise ValueError(f"bad-input case id {case.id!r} in {path.name} and {seen[case.id]}")
            seen[case.id] = path.name
            cases.append(case)
    return cases


def file_hashes(folder: Path) -> dict:
    """``{relative path: md5}`` of every file under ``folder``."""
    return {
        str(p.relative_to(folder)): hashlib.md5(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def assert_names(message: str, names: Sequence[str], case_id: str) -> None:
    low = message.lower()
    missing = [n for n in names if n.lower() not in low]
    assert not missing, f"{case_id}: message does not name {missing}: {message!r}"


CASES = gather()


def test_the_table_is_large_enough():
    assert len(CASES) >= 60, f"only {len(CASES)} bad-input cases"


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_fails_in_one_line_and_keeps_every_file(case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    if case.setup is not None:
        case.setup(tmp_path)
    capsys.readouterr()
    before = file_hashes(tmp_path)
    if case.argv is not None:
        from rsocl.cli.main import main

        argv = [str(a).replace("{tmp}", str(tmp_path)) for a in case.argv]
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse refuses choices and types itself
            rc = exc.code
        err = capsys.readouterr().err
        assert rc == case.rc, f"{case.id}: rsocl {' '.join(argv)} returned {rc}, expected {case.rc}; stderr: {err}"
        assert "Traceback" not in err, f"{case.id}: traceback on stderr: {err}"
        errors = [line for line in err.splitlines() if ": error:" in line]
        assert len(errors) == 1, f"{case.id}: expected one error line, got: {err!r}"
        assert_names(errors[0], case.names, case.id)
    else:
        with pytest.raises(case.errors) as info, warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # a unit slip warns and then fails: the error is tested
            case.api(tmp_path)
        message = str(info.value)
        assert "\n" not in message.strip(), f"{case.id}: message of more than one line: {message!r}"
        assert_names(message, case.names, case.id)
    after = file_hashes(tmp_path)
    changed = {p for p in before if after.get(p) != before[p]}
    assert not changed, f"{case.id}: files changed or removed: {sorted(changed)}"
