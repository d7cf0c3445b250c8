"""Shared fixtures: the thesis' printed numbers (read, never copied)."""

import json
import pathlib

import pytest

import beltjax  # noqa: F401  (enables float64 before any array is made)

REPO = pathlib.Path(__file__).resolve().parents[1]
REFERENCE = REPO.parent / "shared" / "reference" / "thesis_reference.json"


@pytest.fixture(scope="session")
def ref():
    """The thesis reference numbers (../shared/reference/thesis_reference.json)."""
    with open(REFERENCE) as f:
        return json.load(f)


@pytest.fixture(scope="session")
def strip(ref):
    """The thesis' steel strip (Table 3.1) as (L, EA, EI, rhoA)."""
    p = ref["cantilever_strip"]["properties"]
    return p["L"], p["E"] * p["A"], p["E"] * p["I"], p["rho"] * p["A"]
