"""Shared fixtures of the Python checks: where the tarn binary is, how to run it."""
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def tarn_bin() -> str:
    env = os.environ.get("TARN_BIN")
    if env:
        return env
    for profile in ("release", "debug"):
        p = ROOT / "target" / profile / "tarn"
        if p.exists():
            return str(p)
    raise RuntimeError("no tarn binary: build it or set TARN_BIN")


@pytest.fixture
def tarn():
    """Runs `tarn ARGS...`; returns the CompletedProcess (check=False)."""

    def run(*args, check=True):
        r = subprocess.run([tarn_bin(), *map(str, args)], capture_output=True, text=True)
        if check and r.returncode != 0:
            raise AssertionError(f"tarn {' '.join(map(str, args))} failed:\n{r.stderr}")
        return r

    return run
