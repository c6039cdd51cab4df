"""Where the test data lives, whatever folder a test module sits in."""
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent
DATA = TESTS / "data"
GOLDEN = TESTS / "golden"
SHARED_DATA = REPO.parent / "shared" / "data"
