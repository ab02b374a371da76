"""Where the tests find the project's files, whatever folder a test file sits in."""

from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
EXAMPLES = ROOT / "examples"
TEST_DATA = TESTS / "data"
SHARED_DATA = ROOT.parent / "shared" / "data"
