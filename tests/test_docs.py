"""The README and the guides in docs/ stay true: every `hil` command they show exists (its
`--help` runs), every file they link or name exists, and their pytest examples pass as
they stand."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import pytest

from conftest import ROOT
from hil.cli import COMMANDS, main

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: a `hil SUBCOMMAND` in backticks, or at the start of a shell line of a code block (after a
#: prompt)
COMMAND = re.compile(r"`hil ([a-z]+)\b|^(?:\w*\$ +)?(?:\.venv/bin/)?hil ([a-z]+)\b", re.MULTILINE)
CODE_BLOCK = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)
INLINE_CODE = re.compile(r"`[^`\n]+`")
#: a markdown link's target
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
#: a repository path in backticks: a top folder of the repository, then a file
PATH = re.compile(r"`((?:hil|tools|tests|bus_config|robots|docs)/[\w./-]+\.\w+)`")


def _pages_and(pattern: re.Pattern, code_only: bool = False) -> list[tuple[Path, str]]:
    """(page, what ``pattern`` finds there) for every page; with ``code_only``, in its code
    blocks and inline code only (prose says "hil is ...")."""
    found = set()
    for page in PAGES:
        text = page.read_text()
        if code_only:
            text = "\n".join(CODE_BLOCK.findall(text) + INLINE_CODE.findall(text))
        found |= {(page, "".join(match) if isinstance(match, tuple) else match)
                  for match in pattern.findall(text)}
    return sorted(found)


@pytest.mark.parametrize("page, command", _pages_and(COMMAND, code_only=True),
                         ids=lambda v: v.name if isinstance(v, Path) else v)
def test_every_command_the_docs_show_exists_and_its_help_runs(page, command, capsys):
    assert command in COMMANDS, f"{page.name} shows `hil {command}`, which hil does not have"
    with pytest.raises(SystemExit) as ended:
        main([command, "--help"])
    assert ended.value.code == 0


@pytest.mark.parametrize("page, target", [(page, target) for page, target in _pages_and(LINK)
                                          if "://" not in target],   # web pages: not files
                         ids=lambda v: v.name if isinstance(v, Path) else v)
def test_every_link_of_the_docs_reaches_a_file(page, target):
    assert (page.parent / target).exists(), f"{page.name} links {target}, which does not exist"


@pytest.mark.parametrize("page, path", _pages_and(PATH),
                         ids=lambda v: v.name if isinstance(v, Path) else v)
def test_every_repository_path_the_docs_name_exists(page, path):
    assert (ROOT / path).exists(), f"{page.name} names {path}, which does not exist"


def test_the_readme_is_one_screen_of_front_door():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200


@pytest.mark.parametrize("page", ["README.md", "docs/configuration.md"])
def test_the_front_pages_name_every_protocol_hil_ships(page):
    """Issue 64: the README and the bus config reference named three of the five."""
    from hil.protocols import BUILTIN

    text = (ROOT / page).read_text().lower()
    words = {"cia402": "cia 402", "odrive": "odrive", "mit": "mit", "damiao": "damiao",
             "cubemars": "cubemars", "moteus": "moteus", "myactuator": "myactuator",
             "robstride": "robstride"}
    assert set(words) == set(BUILTIN)
    assert [name for name, word in words.items() if word not in text] == []


def test_the_readme_keeps_its_two_set_up_commands():
    text = (ROOT / "README.md").read_text()
    venv = "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && "
    assert f"{venv}.venv/bin/hil up pigot --demo\n" in text
    tests = f"{venv}sh tools/install_lerobot.sh .venv && .venv/bin/python -m pytest -n 2\n"
    assert tests in text
    ci = (ROOT / ".ci" / "run").read_text()       # CI runs the same, step by step
    assert all(step in ci for step in ("pip install --quiet -e '.[test]'",
                                       "sh tools/install_lerobot.sh .venv",
                                       ".venv/bin/python -m pytest -n 2"))


#: a comment's citation of the performance page and the entry it names: a heading in double
#: quotes (`docs/performance.md, "Frames as their parts over Zenoh (...)"`) or a dated
#: entry's date (`docs/performance.md, 2026-12-01`)
PERFORMANCE_CITATION = re.compile(
    r'docs/performance\.md(?:,\s*(?:"(?P<heading>[^"]+)"|(?P<date>\d{4}-\d{2}-\d{2})))?')
#: what a comment's or a docstring's continuation line starts with
CONTINUATION = re.compile(r"\n\s*(?:#:?\s*)?")


def _performance_citations() -> list[tuple[str, str | None, str | None]]:
    """('file:line', heading, date) of every citation of docs/performance.md in hil's
    modules; a citation's next two lines joined on, where a heading wraps."""
    found = []
    for path in sorted((ROOT / "hil").rglob("*.py")):
        lines = path.read_text().splitlines()
        for number, line in enumerate(lines):
            at = line.find("docs/performance.md")
            if at < 0:
                continue
            text = CONTINUATION.sub(" ", "\n".join([line[at:], *lines[number + 1:number + 3]]))
            citation = PERFORMANCE_CITATION.match(text)
            found.append((f"{path.relative_to(ROOT)}:{number + 1}", citation["heading"],
                          citation["date"]))
    return found


def test_every_performance_entry_the_code_cites_exists():
    """Issue 66: measured figures stand in docs/performance.md, and a comment that cites the
    page names its entry by heading or date; "Recording" and bare citations named none."""
    headings = [re.sub(r"^#+\s*", "", line) for line in
                (ROOT / "docs" / "performance.md").read_text().splitlines()
                if line.startswith("#")]
    citations = _performance_citations()
    assert citations, "no citation of docs/performance.md found in hil/: the scan is broken"
    wrong = []
    for where, heading, date in citations:
        if heading is None and date is None:
            wrong.append(f"{where}: names no entry (give its heading in double quotes, or "
                         "its date)")
        elif heading is not None and " ".join(heading.split()) not in headings:
            wrong.append(f"{where}: no heading {heading!r}")
        elif date is not None and not any(date in text for text in headings):
            wrong.append(f"{where}: no entry dated {date}")
    assert wrong == [], "docs/performance.md cited wrongly:\n" + "\n".join(wrong)


@pytest.mark.slow
@pytest.mark.parametrize("page", ["README.md", "docs/testing.md"])
def test_the_pytest_examples_pass_as_they_stand_from_an_empty_folder(page, tmp_path):
    """Every test a page shows, pasted into a file in an empty folder and run with pytest and
    --junitxml as a user would (hil's pytest plugin loaded as installed, ``hil`` on PATH)."""
    examples = [block for block in re.findall(r"```python\n(.*?)```",
                                              (ROOT / page).read_text(), re.DOTALL)
                if "def test_" in block]
    assert examples, f"{page} shows no pytest example"
    for number, example in enumerate(examples):
        (tmp_path / f"test_example_{number}.py").write_text(example)
    report = tmp_path / "report.xml"
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           f"--junitxml={report}", str(tmp_path)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=280,
                          env={**os.environ, "PATH": path})
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    cases = ElementTree.parse(report).getroot().iter("testcase")
    assert len(list(cases)) == len(examples)
