from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHIPPED = REPO / "datasets"
# Real datasets live beside the repository (../shared/data), never inside it.
SHARED = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared() -> Path:
    if not SHARED.exists():
        pytest.skip(f"{SHARED} not present (real datasets live beside the repository)")
    return SHARED


@pytest.fixture(scope="session")
def shipped() -> Path:
    return SHIPPED
