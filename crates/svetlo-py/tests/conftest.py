"""Shared fixtures of the Python package's tests (run with pytest from anywhere)."""

import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCENES = ROOT / "scenes"


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The `svetlo` binary built from this checkout (SVETLO_CLI overrides the path)."""
    p = pathlib.Path(os.environ.get("SVETLO_CLI", ROOT / "target" / "release" / "svetlo"))
    if not p.is_file():
        pytest.fail(f"the svetlo CLI is not at {p}: build it first (cargo build --release -p svetlo-cli) or set SVETLO_CLI")
    return p


@pytest.fixture(scope="session")
def cbox_path() -> pathlib.Path:
    return SCENES / "cornell-box.xml"
