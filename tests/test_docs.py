"""The README and the docs run as written: each page's Python blocks in order, in a fresh
process (a page may start Taichi as it likes), and the `circles` commands of the README and
Getting started, with short durations (`docs_blocks`). Each runs in a folder of its own that
holds a copy of `scenes/`, as a checkout does."""

import re
import shutil
import subprocess
import sys

import pytest

import docs_blocks
from process_util import child_env, run_cli

SCRIPTS = [page for page in docs_blocks.PAGES if docs_blocks.python_script(page)]
COMMAND_PAGES = ["README.md", "docs/getting-started.md"]


def _checkout_like(tmp_path):
    """tmp_path with a copy of the scenes, its sweep measuring for seconds instead of minutes."""
    shutil.copytree(docs_blocks.ROOT / "scenes", tmp_path / "scenes")
    sweep = tmp_path / "scenes" / "eos_sweep.toml"
    text = sweep.read_text()
    for key, value in (("repeats", "1"), ("equilibrate", "1.0"), ("measure", "2.0"), ("blocks", "2")):
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    sweep.write_text(text)
    return tmp_path


@pytest.mark.parametrize("page", SCRIPTS)
def test_python_blocks_run_in_order(page, tmp_path):
    script = docs_blocks.python_script(page)
    done = subprocess.run([sys.executable, "-c", script], cwd=_checkout_like(tmp_path), env=child_env(),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{page}:\n{done.stderr[-3000:]}"


def test_every_skipped_block_says_why():
    for page in docs_blocks.PAGES:
        for language in ("python", ""):
            for line, _, skip in docs_blocks.blocks(page, language):
                assert skip is None or len(skip.split()) >= 3, f"{page}:{line}: give the reason to skip"


@pytest.mark.parametrize("page", COMMAND_PAGES)
def test_documented_commands_run(page, tmp_path):
    commands = docs_blocks.commands(page)
    assert len(commands) >= 3  # the collector still finds them
    where = _checkout_like(tmp_path)
    for words in commands:
        args = docs_blocks.short_command(words)[1:]
        done = run_cli(args, where, timeout=600)
        assert done.returncode == 0, f"{page}: {' '.join(words)}\n{done.stderr[-3000:]}"


def test_every_picture_the_pages_show_is_committed():
    """Each `outputs/` picture the docs pages link to, and that the site's hook publishes, is
    tracked by git, not just present here (an ignored one breaks the strict build of a clone)."""
    root = docs_blocks.ROOT
    if not (root / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout: nothing to ask git")
    sys.path.insert(0, str(root))
    from mkdocs_hooks import PICTURES

    linked = {m for page in (root / "docs").glob("*.md")
              for m in re.findall(r"\]\((outputs/[^)\s]+\.(?:png|gif))\)", page.read_text())}
    assert linked <= set(PICTURES), sorted(linked - set(PICTURES))
    for path in PICTURES:
        done = subprocess.run(["git", "ls-files", "--error-unmatch", path], cwd=root, capture_output=True)
        assert done.returncode == 0, f"{path} is not committed (an ignored path? see .gitignore)"
