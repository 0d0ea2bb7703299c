"""Shared fixtures: the bundled example and the CLI's own outputs on it.

The CLI is the reference: `DYNOCOMP_BIN` (scripts/python_test.sh sets it to
the release build), else target/release/dynocomp. The tests fail, not skip,
when it is missing.
"""

import json
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "data" / "example"
FS = 51200


def cli_path():
    p = Path(os.environ.get("DYNOCOMP_BIN", ROOT / "target" / "release" / "dynocomp"))
    assert p.exists(), f"{p}: build the CLI first (cargo build --release -p dynocomp --bin dynocomp)"
    return p


def run_cli(*args, check=True):
    """Run `dynocomp ARGS`; returns the completed process (text)."""
    r = subprocess.run([str(cli_path()), *map(str, args)], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"dynocomp {' '.join(map(str, args))} failed:\n{r.stderr}")
    return r


def cli_error(*args):
    """The CLI's one-line error message (without `error: `) for ARGS."""
    r = run_cli(*args, check=False)
    assert r.returncode != 0, f"dynocomp {args} should have failed"
    line = [l for l in r.stderr.splitlines() if l.startswith("error: ")][-1]
    return line[len("error: "):]


@pytest.fixture(scope="session")
def cli_design(tmp_path_factory):
    """`dynocomp design` on the bundled example (as scripts/demo.sh runs it,
    with --json): (image path, JSON summary)."""
    d = tmp_path_factory.mktemp("cli")
    img = d / "example.dcimg"
    r = run_cli("design", "--frf", EXAMPLE / "frf.uff", "--fs", FS, "--idle", EXAMPLE / "idle.csv",
                "--out", img, "--json")
    return img, json.loads(r.stdout)


@pytest.fixture(scope="session")
def cli_compensated(cli_design, tmp_path_factory):
    """`dynocomp compensate` (box mode) of the bundled measured record."""
    img, _ = cli_design
    out = tmp_path_factory.mktemp("cli") / "compensated.csv"
    run_cli("compensate", "--coeffs", img, "--input", EXAMPLE / "measured.csv", "--output", out)
    return out
