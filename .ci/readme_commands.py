"""Print the commands of README.md's "Two commands" section, one per line, exactly as written.

    python3 .ci/readme_commands.py README.md

CI runs what this prints (.ci/readme.sh), so the README cannot drift from what CI proves. Exit 2,
naming the cause, when the section, its bash block or its two commands are not there.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

HEADING = "## Two commands"
COUNT = 2


def two_commands(readme: str) -> list[str]:
    """The command lines (blank and comment-only lines left out) of the first ```bash block of the
    "Two commands" section; ValueError naming what is missing."""
    section = re.search(rf"^{re.escape(HEADING)}[ \t]*\n(.*?)(?=^## |\Z)", readme, flags=re.M | re.S)
    if section is None:
        raise ValueError(f"no '{HEADING}' section")
    block = re.search(r"^```bash\n(.*?)^```", section.group(1), flags=re.M | re.S)
    if block is None:
        raise ValueError(f"no ```bash block in the '{HEADING}' section")
    lines = [ln for ln in block.group(1).splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if len(lines) != COUNT:
        raise ValueError(f"{len(lines)} commands in the '{HEADING}' block, expected {COUNT}: {lines}")
    return lines


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: readme_commands.py README.md", file=sys.stderr)
        return 2
    try:
        commands = two_commands(Path(argv[0]).read_text())
    except (OSError, ValueError) as exc:
        print(f"readme_commands: {argv[0]}: {exc}", file=sys.stderr)
        return 2
    print("\n".join(commands))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
