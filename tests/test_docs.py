"""The README and docs/*.md stay honest: one page, links that resolve, commands that parse.

Fast and light: reads Markdown files and builds ``nlosplan``'s argument parser; runs nothing.
"""

from __future__ import annotations

import ast
import itertools
import re
import shlex
import shutil
from pathlib import Path

import pytest

from nlosplan.errors import UserError

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 200

_FENCE = re.compile(r"^\s*(```|~~~)")
_INLINE_CODE = re.compile(r"`+[^`]*`+")
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")  # [text](target "title")
_REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\"[^\"]*\")?\s*$")  # [name]: target
_HTML = re.compile(r"<(?:img|a)\b[^>]*?\b(?:src|href)\s*=\s*[\"']([^\"']+)[\"']", re.IGNORECASE)
_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")  # http:, https:, mailto:, ...
# Placeholders of the command lines and what the parser gets instead.
_PLACEHOLDERS = {"PORT": "/dev/null", "HOST": "localhost", "FILE": "file.txt", "DIR": "dir", "PATH": "path",
                 "ID": "run-1", "NAME": "name", "N": "1"}


def markdown_files(root: Path) -> list[Path]:
    """``README.md`` and every ``docs/*.md`` under ``root``."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def _prose_lines(text: str):
    """(line number, line) outside fenced code blocks, inline code spans removed."""
    fence = None
    for number, line in enumerate(text.splitlines(), 1):
        m = _FENCE.match(line)
        if m:
            fence = None if fence == m.group(1) else (fence or m.group(1))
            continue
        if fence is None:
            yield number, _INLINE_CODE.sub("", line)


def link_targets(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of every link and image in a Markdown file, code excluded."""
    found = []
    for number, line in _prose_lines(path.read_text(encoding="utf-8")):
        for rx in (_LINK, _REF_DEF, _HTML):
            found += [(number, m.group(1)) for m in rx.finditer(line)]
    return found


def broken_links(root: Path) -> list[str]:
    """Every relative link or image of README.md and docs/*.md that names no existing file.

    Web addresses and same-page anchors are not checked; ``#anchor`` parts are ignored.
    Absolute paths count as broken: they do not travel with the repository.
    """
    broken = []
    for md in markdown_files(root):
        for number, target in link_targets(md):
            if _SCHEME.match(target) or target.startswith("#"):
                continue
            file_part = target.split("#", 1)[0].split("?", 1)[0]
            where = f"{md.relative_to(root)}:{number}: {target}"
            if file_part.startswith("/"):
                broken.append(where + " (absolute path)")
            elif not (md.parent / file_part).exists():
                broken.append(where)
    return broken


def code_blocks(text: str, language: str) -> list[tuple[int, list[str]]]:
    """(first line number, lines) of every fenced block opened with ```language."""
    blocks, current, start = [], None, 0
    for number, line in enumerate(text.splitlines(), 1):
        if current is None and line.strip() == f"```{language}":
            current, start = [], number + 1
        elif current is not None and line.strip().startswith("```"):
            blocks.append((start, current))
            current = None
        elif current is not None:
            current.append(line)
    return blocks


def command_lines(text: str) -> list[tuple[int, str]]:
    """(line number, command) for each ``nlosplan`` line of the bash blocks; continuations joined."""
    commands = []
    for start, lines in code_blocks(text, "bash"):
        pending, first = "", 0
        for offset, line in enumerate(lines):
            if not pending and not line.lstrip().startswith("nlosplan "):
                continue
            first = first if pending else start + offset
            # a trailing backslash continues the command (a comment may not follow it)
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            commands.append((first, pending + line))
            pending = ""
    return commands


def expand(command: str) -> list[list[str]]:
    """The argument lists a documented command line stands for, without the leading ``nlosplan``.

    Comments are stripped; ``[--opt]`` is optional (with and without); ``a | b`` are
    alternatives for one word; placeholders (PORT, FILE, ...) become dummies.
    """
    tokens = shlex.split(command, comments=True)
    if not tokens or tokens[0] != "nlosplan":
        raise ValueError(f"not an nlosplan command: {command!r}")
    choices: list[list[list[str]]] = []
    i = 1
    while i < len(tokens):
        tok = tokens[i]
        if tok.startswith("[") and tok.endswith("]"):
            choices.append([[], tok[1:-1].split()])
        elif tok == "|" and choices and i + 1 < len(tokens):
            choices[-1].append([tokens[i + 1]])
            i += 1
        else:
            choices.append([[tok]])
        i += 1
    variants = []
    for combo in itertools.product(*choices):
        args = [a for part in combo for a in part]
        args = [re.sub(r"\b(" + "|".join(_PLACEHOLDERS) + r")\b", lambda m: _PLACEHOLDERS[m.group(1)], a)
                for a in args]
        variants.append(args)
    return variants


def unparsable_commands(parser, path: Path) -> list[str]:
    """Every documented ``nlosplan`` command of a Markdown file that the parser refuses."""
    bad = []
    for number, command in command_lines(path.read_text(encoding="utf-8")):
        for args in expand(command):
            try:
                parser.parse_args(args)
            except (UserError, SystemExit) as exc:
                bad.append(f"{path.name}:{number}: nlosplan {shlex.join(args)}: {exc}")
    return bad


@pytest.fixture(scope="module")
def parser():
    from nlosplan.cli import build_parser

    return build_parser()


def test_readme_is_one_page_with_the_setup_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= README_MAX_LINES
    setup = [line.strip() for _, block in code_blocks(text, "bash") for line in block]
    assert "make demo" in setup and "make test" in setup
    # the two commands come before the first docs link, on the first screen
    assert text.index("make demo") < text.index("make test") < text.index("](docs/")


def test_every_link_and_image_resolves():
    assert broken_links(ROOT) == []


def test_every_docs_page_is_linked_from_the_index():
    index = {t.split("#", 1)[0] for _, t in link_targets(ROOT / "docs" / "index.md")}
    pages = {p.name for p in (ROOT / "docs").glob("*.md")} - {"index.md"}
    assert pages <= index, f"docs pages missing from docs/index.md: {sorted(pages - index)}"


def test_link_check_catches_a_broken_link(tmp_path):
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    before = set(broken_links(tmp_path))
    readme = tmp_path / "README.md"
    text = readme.read_text(encoding="utf-8")
    assert "(docs/design_tradeoffs_loc.png)" in text
    readme.write_text(text.replace("(docs/design_tradeoffs_loc.png)", "(docs/design_tradeoffs_lox.png)", 1))
    (tmp_path / "docs" / "extra.md").write_text(
        "# x\n\n[ok](index.md#anchor) [web](https://example.org/a.md) [here](#top)\n"
        "`[in code](missing-in-code.md)`\n\n```\n[in a block](missing-in-block.md)\n```\n\n"
        "[gone](gone.md#part) ![pic](gone.png)\n[ref]: also-gone.md\n[abs](/etc/hosts)\n",
        encoding="utf-8")
    new = sorted(set(broken_links(tmp_path)) - before)
    assert len(new) == 5, new
    assert new[0].startswith("README.md:") and new[0].endswith(": docs/design_tradeoffs_lox.png")
    assert [n.split(": ", 1)[1] for n in new[1:]] == [
        "gone.md#part", "gone.png", "also-gone.md", "/etc/hosts (absolute path)"]


def test_command_notation_expands():
    assert expand("nlosplan study resolution | bins [--quick]   # zones; bins") == [
        ["study", "resolution"], ["study", "resolution", "--quick"], ["study", "bins"], ["study", "bins", "--quick"]]
    assert expand("nlosplan rig capture --lidar PORT --store 'a b.db'") == [
        ["rig", "capture", "--lidar", "/dev/null", "--store", "a b.db"]]
    text = "```bash\nmake test\nnlosplan simulate --out x.npy \\\n   --plot x.png  # one\n```\n"
    assert [(n, " ".join(c.split())) for n, c in command_lines(text)] == [
        (3, "nlosplan simulate --out x.npy --plot x.png # one")]


def test_readme_commands_parse(parser):
    readme = ROOT / "README.md"
    commands = command_lines(readme.read_text(encoding="utf-8"))
    assert len(commands) >= 30  # the command list is there
    assert unparsable_commands(parser, readme) == []


def test_docs_commands_parse(parser):
    bad = [b for page in sorted((ROOT / "docs").glob("*.md")) for b in unparsable_commands(parser, page)]
    assert bad == []


def test_command_check_catches_a_wrong_command(parser, tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```bash\nnlosplan sensor list\nnlosplan simulate --no-such-flag 3   # wrong\n"
                    "nlosplan design --quick [--jsn]\n```\n", encoding="utf-8")
    bad = unparsable_commands(parser, page)
    assert [b.split(": nlosplan ", 1)[0] for b in bad] == ["page.md:3", "page.md:4"]
    assert "--no-such-flag" in bad[0] and "--jsn" in bad[1]


def test_python_examples_are_python():
    for md in markdown_files(ROOT):
        for start, block in code_blocks(md.read_text(encoding="utf-8"), "python"):
            try:
                ast.parse("\n".join(block))
            except SyntaxError as exc:
                pytest.fail(f"{md.relative_to(ROOT)}:{start + (exc.lineno or 1) - 1}: {exc.msg}")
