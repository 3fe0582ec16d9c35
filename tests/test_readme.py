"""Every code block of the README and of the documentation (docs/**/*.md) runs as written.

The convention, by the block's language:

- ```python: saved as a script and run by the package's Python in a fresh folder; it must succeed and print. A
  ``print(...)`` line whose comment ends in ``= VALUE UNIT`` states what it prints: VALUE, sign included, must be in
  the output.
- ```console: its ``$ `` lines (a line ending in a backslash goes on with the next) run as one bash script
  (``set -euo pipefail``) in a fresh folder, with the package's ``finrft`` and ``python`` first on PATH; the lines
  without ``$ `` are output, not checked.
- ```toml: must parse.
- anything else (```text: usage lines, output) is not run.

An HTML comment on the line just before a block says otherwise: ``<!-- not run: REASON -->`` leaves it out (it
installs software, runs for minutes, needs files of yours), ``<!-- slow: REASON -->`` runs it with the long
studies (``pytest -m slow``). The examples/ scripts run in tests/test_examples.py.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"(?:^<!-- (?P<mark>not run|slow): (?P<why>[^\n]*?) -->\n)?^```(?P<lang>[\w-]*)\n(?P<body>.*?)^```$",
                   flags=re.S | re.M)
RUN = ("python", "console", "toml")
STATED = re.compile(r"^\s*print\(.*#.*= (?P<value>[-+]?\d[\d.]*) \S+\s*$", flags=re.M)


@dataclass(frozen=True)
class Block:
    page: Path
    line: int
    lang: str
    body: str
    mark: str | None
    why: str | None

    @property
    def name(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    text = page.read_text()
    return [Block(page, text.count("\n", 0, m.start("lang")) + 1, m["lang"], m["body"], m["mark"], m["why"])
            for m in FENCE.finditer(text)]


ALL = [block for page in PAGES for block in blocks(page)]


def commands(body: str) -> list[str]:
    """The ``$ `` commands of a console block, continuation lines joined."""
    found: list[str] = []
    going_on = False
    for line in body.splitlines():
        if going_on:
            found[-1] += "\n" + line
        elif line.startswith("$ "):
            found.append(line[2:])
        else:
            continue
        going_on = line.endswith("\\")
    return found


def _slow(block: Block) -> bool:
    """Whether a block runs with the slow studies: marked so, or on a page other than the README (the guides' and
    results' blocks, a few minutes in all, run in CI beside the fast suite)."""
    return block.mark == "slow" or block.page.name != "README.md"


def _params(lang: str, slow: bool) -> list:
    chosen = [b for b in ALL if b.lang == lang and b.mark != "not run" and _slow(b) == slow]
    marks = [pytest.mark.slow] if slow else []
    return [pytest.param(b, id=b.name, marks=marks) for b in chosen]


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    return env


def test_the_pages_have_blocks_that_run():
    readme = [b for b in ALL if b.page.name == "README.md"]
    assert sum(b.lang == "python" for b in readme) >= 2
    tour = [b for b in readme if b.lang == "console" and b.mark is None]
    assert len(tour) >= 3, "the README's tour runs its commands"
    assert any(b.lang == "python" for b in ALL if b.page.parent.name == "guide")


def test_every_mark_says_why():
    for block in ALL:
        if block.mark:
            assert block.why and block.why.strip(), f"{block.name}: a '{block.mark}' mark needs its reason"
            assert block.lang in RUN, f"{block.name}: only blocks that would run take a mark"


def test_quick_start_is_two_commands():
    """The README's Quick start: one line installs and runs the main job, one installs and runs the tests."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    (block,) = [b for b in FENCE.finditer(section)]
    assert commands(block["body"]) == ["pip install . && finrft drag --json", "pip install '.[test]' && pytest -q"]


def test_the_readme_is_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 300


@pytest.mark.parametrize("block", [pytest.param(b, id=b.name) for b in ALL if b.lang == "toml"])
def test_toml_block_parses(block):
    tomllib.loads(block.body)


def _run_python(block: Block, tmp_path: Path) -> None:
    script = tmp_path / "example.py"
    script.write_text(block.body)
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          env=_environment())
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip(), "an example should show its result"
    for stated in STATED.finditer(block.body):
        # a number of its own, not part of another ("26.64" is not what "-26.64" says)
        shown = re.search(rf"(?<![-+\d.]){re.escape(stated['value'])}(?![\d])", done.stdout)
        assert shown, f"{block.name}: the comment says {stated['value']}, the block prints {done.stdout!r}"


def _run_console(block: Block, tmp_path: Path) -> None:
    found = commands(block.body)
    assert found, f"{block.name}: a console block without '$ ' commands"
    script = "set -euo pipefail\n" + "\n".join(found) + "\n"
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=1200,
                          env=_environment())
    assert done.returncode == 0, f"{script}\n{done.stderr[-3000:]}"


@pytest.mark.parametrize("block", _params("python", slow=False))
def test_python_block_runs(block, tmp_path):
    _run_python(block, tmp_path)


@pytest.mark.parametrize("block", _params("console", slow=False))
def test_console_block_runs(block, tmp_path):
    _run_console(block, tmp_path)


@pytest.mark.parametrize("block", _params("python", slow=True))
def test_slow_python_block_runs(block, tmp_path):
    _run_python(block, tmp_path)


@pytest.mark.parametrize("block", _params("console", slow=True))
def test_slow_console_block_runs(block, tmp_path):
    _run_console(block, tmp_path)
