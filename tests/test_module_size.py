"""No module of the package over 400 lines: a module that has to be scrolled through in pieces hides
its own structure (the object core was split for this; the fleet core was written within it)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 400


def test_no_module_of_the_package_is_over_400_lines():
    long = {str(p.relative_to(ROOT)): n for p in sorted((ROOT / "swarmbox").rglob("*.py"))
            if (n := len(p.read_text().splitlines())) > LIMIT}
    assert not long, f"modules over {LIMIT} lines: {long}"
