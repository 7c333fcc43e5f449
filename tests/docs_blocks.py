"""The code of the README and the docs pages, as a reader would run it: the Python blocks of a
page in order (one script, so that a block may use what an earlier one made), and the
`circles ...` commands of its shell blocks.

A block is skipped when the line before its fence is ``<!-- test: skip REASON -->`` (an HTML
comment, not shown on the page): for a block that needs a GPU or a cluster scheduler. Nothing
else is changed in a Python block. A command's simulated duration is shortened
(`short_command`), since the test checks that it runs, not what it measures.
"""

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]

_FENCE = re.compile(r"^```(\w*)[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)
_SKIP = re.compile(r"<!--\s*test:\s*skip\s+(.*?)\s*-->\s*$")
#: The simulated seconds a documented command runs in the test.
SHORT_DURATION = "0.5"


def blocks(page, language):
    """[(line, code, reason to skip or None)] of the fenced blocks of `language` ("python", or
    "" for the plain blocks that hold shell commands) in the page, in order."""
    text = (ROOT / page).read_text()
    found = []
    for match in _FENCE.finditer(text):
        if match.group(1) != language:
            continue
        line = text.count("\n", 0, match.start()) + 1
        before = text[:match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        skip = _SKIP.search(before)
        found.append((line, match.group(2), skip.group(1) if skip else None))
    return found


def python_script(page):
    """The page's Python blocks that are not skipped, as one script; None when there are none."""
    parts = [f"# {page}:{line}\n{code}" for line, code, skip in blocks(page, "python") if skip is None]
    return "\n".join(parts) if parts else None


def commands(page):
    """The `circles ...` commands of the page's plain blocks, in order, each as a list of words
    (continued lines joined, comments dropped); a synopsis (with [OPTIONAL] parts) is not one."""
    found = []
    for _, code, skip in blocks(page, ""):
        if skip is not None:
            continue
        for line in code.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words[:1] == ["circles"] and not any(w.startswith("[") for w in words):
                found.append(words)
    return found


def short_command(words):
    """The command with a short simulated duration: --duration set to SHORT_DURATION (added to a
    `circles run`)."""
    words = list(words)
    if "--duration" in words:
        words[words.index("--duration") + 1] = SHORT_DURATION
    elif words[1:2] == ["run"]:
        words += ["--duration", SHORT_DURATION]
    return words
