"""Fixtures: the repository root (the tests run from it, so world paths read as the CLI's do)
and the `ftcbf` binary the package's numbers are compared with."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def in_repo(monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(REPO)
    return REPO


@pytest.fixture(scope="session")
def ftcbf_bin() -> Path:
    """`$FTCBF_BIN`, else target/release/ftcbf (built by `cargo test --release --workspace
    --no-run`). Missing, the comparison tests fail: they are the point of the suite."""
    path = Path(os.environ.get("FTCBF_BIN", REPO / "target" / "release" / "ftcbf"))
    assert path.is_file(), f"the ftcbf binary is not at {path}: build it or set FTCBF_BIN"
    return path


@pytest.fixture(scope="session")
def cli(ftcbf_bin: Path):
    """Runs `ftcbf ARGS...` in the repository root: (exit code, stdout, stderr)."""

    def run(*args: str) -> tuple[int, str, str]:
        p = subprocess.run(
            [str(ftcbf_bin), *args], cwd=REPO, capture_output=True, text=True, timeout=600
        )
        return p.returncode, p.stdout, p.stderr

    return run


@pytest.fixture(scope="session")
def cli_json(cli):
    def run(*args: str):
        code, out, err = cli(*args)
        assert code in (0, 3), f"ftcbf {' '.join(args)} exited {code}: {err}"
        return json.loads(out)

    return run
