"""The documentation as a user reads it: every ``slopedist ...`` command the docs show names
commands and options that exist (with valid choices), and every relative link and ``#anchor``
between the docs resolves (GitHub's anchor rules)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path
from typing import NamedTuple

import click
import pytest

from slopedist.cli import cli

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").glob("*.md"))]

_FENCE = re.compile(r"^\s*(```|~~~)")
_INLINE = re.compile(r"`(slopedist [^`]+)`")
_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")


class DocCommand(NamedTuple):
    """A ``slopedist`` command line shown in a doc, and where."""

    where: str
    text: str


def _code_lines(text: str) -> list[tuple[int, str]]:
    """Lines of fenced and indented code blocks, with their 1-based line numbers."""
    lines = text.splitlines()
    out: list[tuple[int, str]] = []
    in_fence = False
    in_indented = False  # an indented block: lines of 4+ spaces after a blank line
    for n, line in enumerate(lines, 1):
        if _FENCE.match(line):
            in_fence = not in_fence
            continue
        after_blank = n < 2 or not lines[n - 2].strip()
        in_indented = line.startswith("    ") and (in_indented or after_blank)
        if in_fence or in_indented:
            out.append((n, line.strip()))
    return out


def doc_commands(path: Path) -> list[DocCommand]:
    """Every ``slopedist`` command of a doc: code-block lines (joined over ``\\``
    continuations) and inline code spans (which may wrap over lines)."""
    text = path.read_text(encoding="utf-8")
    found: list[DocCommand] = []
    pending: tuple[int, str] | None = None
    for n, line in _code_lines(text):
        if pending is not None:
            pending = (pending[0], pending[1] + " " + line)
        else:
            match = re.search(r"(?:^|\$ |&& |; )(slopedist\s.*)", line)
            if match is None:
                continue
            pending = (n, match.group(1))
        if pending[1].endswith("\\"):
            pending = (pending[0], pending[1][:-1])
            continue
        found.append(DocCommand(f"{path.name}:{pending[0]}", pending[1]))
        pending = None
    prose = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    for match in _INLINE.finditer(prose):
        line = prose.count("\n", 0, match.start()) + 1
        found.append(DocCommand(f"{path.name}:~{line}", " ".join(match.group(1).split())))
    return found


def _tokens(command: str) -> list[str]:
    command = command.split(" #")[0]
    command = re.split(r"\s(?:\||&&|;|>|2>)\s", command)[0]
    try:
        words = shlex.split(command)
    except ValueError:
        words = command.split()
    return [w.strip("[]") for w in words[1:] if w.strip("[]")]


def _is_placeholder(value: str) -> bool:
    return "…" in value or "..." in value or value.startswith("$") or value.isupper()


def command_problems(command: str) -> list[str]:
    """What in one ``slopedist ...`` line does not exist: a subcommand, an option, a choice."""
    tokens = _tokens(command)
    node: click.Command = cli
    ctx = click.Context(cli)
    while isinstance(node, click.Group) and tokens and not _is_placeholder(tokens[0]):
        if tokens[0].startswith("-"):
            tokens = tokens[1:]
            continue
        sub = node.get_command(ctx, tokens[0])
        if sub is None:
            return [f"no command {tokens[0]!r}"]
        node, tokens = sub, tokens[1:]
    options: dict[str, click.Parameter] = {"-h": cli.params[0], "--help": cli.params[0]}
    for param in node.params:
        if isinstance(param, click.Option):
            options.update({name: param for name in param.opts + param.secondary_opts})
    problems = []
    for i, token in enumerate(tokens):
        if not token.startswith("--") and not re.fullmatch(r"-[a-zA-Z]", token):
            continue
        name, _, inline_value = token.partition("=")
        param = options.get(name)
        if param is None:
            problems.append(f"{node.name}: no option {name}")
            continue
        value = inline_value or (tokens[i + 1] if i + 1 < len(tokens) else "")
        if (
            isinstance(param, click.Option)
            and not param.is_flag
            and isinstance(param.type, click.Choice)
            and value
            and not value.startswith("-")
            and not _is_placeholder(value)
        ):
            for choice in value.split("|"):
                if choice not in param.type.choices:
                    problems.append(f"{node.name} {name}: {choice!r} is not one of the choices")
    return problems


def github_anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, markup and punctuation removed, spaces →
    hyphens (letters of any script, digits, ``_`` and ``-`` kept)."""
    text = re.sub(r"`|\*\*|\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The anchors of a Markdown file's headings (duplicates numbered ``-1``, ``-2``, ...)."""
    seen: dict[str, int] = {}
    out = set()
    in_fence = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line):
            in_fence = not in_fence
            continue
        match = None if in_fence else _HEADING.match(line)
        if match:
            slug = github_anchor(match.group(2))
            out.add(slug if slug not in seen else f"{slug}-{seen[slug]}")
            seen[slug] = seen.get(slug, 0) + 1
    return out


def link_problems(path: Path) -> list[str]:
    """Relative links of a doc whose file or ``#anchor`` does not exist."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.DOTALL)
    problems = []
    for match in _LINK.finditer(text):
        target = match.group(1)
        if re.match(r"[a-z]+:", target):
            continue
        file_part, _, anchor = target.partition("#")
        linked = (path.parent / file_part).resolve() if file_part else path
        if not linked.exists():
            problems.append(f"{path.name}: {target}: no file {file_part}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            problems.append(f"{path.name}: {target}: no heading with anchor #{anchor}")
    return problems


def test_checkers_see_what_is_wrong(tmp_path: Path) -> None:
    assert command_problems("slopedist run F --calib c --boxes b --overlay") == []
    assert command_problems("slopedist run F --calib c --no-such") == ["run: no option --no-such"]
    assert command_problems("slopedist eval kitti-tracking D --boxes lidar") == [
        "kitti-tracking --boxes: 'lidar' is not one of the choices"
    ]
    assert command_problems("slopedist frobnicate") == ["no command 'frobnicate'"]
    assert github_anchor("`slopedist calibrate`: the mount (θ0, h) from a drive") == (
        "slopedist-calibrate-the-mount-θ0-h-from-a-drive"
    )
    doc = tmp_path / "a.md"
    doc.write_text("# Top: `x`\n\n## Top: `x`\n\n[ok](#top-x-1) [bad](#nowhere) [f](b.md)\n")
    assert link_problems(doc) == [
        "a.md: #nowhere: no heading with anchor #nowhere",
        "a.md: b.md: no file b.md",
    ]
    doc.write_text(
        "```bash\nslopedist run F \\\n    --bogus 1\n```\n\n    slopedist demo --jobs 1\n"
    )
    assert [c.text for c in doc_commands(doc)] == [
        "slopedist run F  --bogus 1",
        "slopedist demo --jobs 1",
    ]


def test_the_docs_show_many_commands() -> None:
    commands = [c for doc in DOCS for c in doc_commands(doc)]
    assert len(commands) > 100
    assert any("--snapshot 45" in c.text for c in commands)  # an indented block (viewers.md)


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_every_command_in_the_docs_exists(doc: Path) -> None:
    problems = [
        f"{c.where}: {p}: {c.text}" for c in doc_commands(doc) for p in command_problems(c.text)
    ]
    assert problems == []


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_every_relative_link_and_anchor_resolves(doc: Path) -> None:
    assert link_problems(doc) == []


def _all_commands(group: click.Group, ctx: click.Context) -> list[click.Command]:
    found: list[click.Command] = []
    for name in group.list_commands(ctx):
        sub = group.get_command(ctx, name)
        assert sub is not None
        found.append(sub)
        if isinstance(sub, click.Group):
            found += _all_commands(sub, ctx)
    return found


def test_every_doc_a_help_text_names_exists() -> None:
    ctx = click.Context(cli)
    commands = _all_commands(cli, ctx)
    texts = [c.help or "" for c in commands] + [
        p.help or "" for c in commands for p in c.params if isinstance(p, click.Option)
    ]
    named = {m for t in texts for m in re.findall(r"docs/[\w.-]+\.md", t)}
    assert named  # the help texts do point to the docs
    assert sorted(n for n in named if not (ROOT / n).exists()) == []
    assert [t for t in texts if "README" in t] == []  # the README is a front door, not a reference


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` (below ``slopedist``) is a module, or an attribute of one."""
    import importlib

    parts = dotted.split(".")
    for n in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(["slopedist", *parts[:n]]))
        except ImportError:
            continue
        for name in parts[n:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


def test_the_layer_table_names_modules_that_exist() -> None:
    """CONTRIBUTING's layer table and its notes name modules and classes of the layout."""
    text = (ROOT / "CONTRIBUTING.md").read_text(encoding="utf-8")
    table = text.split("## How the code is laid out", 1)[1].split("## Habits", 1)[0]
    names = {
        n
        for n in re.findall(r"`([a-z_]+(?:\.[A-Za-z_]+)*)`", table)
        if "." in n or (ROOT / "src" / "slopedist" / n).is_dir()
    }
    assert len(names) > 15
    assert [n for n in sorted(names) if not _resolves(n)] == []


def test_the_code_map_of_the_method_names_files_that_exist() -> None:
    """docs/method.md's "where each step runs" and its code column name files and functions
    of the layout."""
    text = (ROOT / "docs" / "method.md").read_text(encoding="utf-8")
    src = ROOT / "src" / "slopedist"
    code_map = text.split("Where each step runs", 1)[1].split("\n\n", 1)[0]
    paths = set(re.findall(r"`((?:[a-z_]+/)+(?:[a-z_]+\.py)?)`", code_map))
    assert len(paths) > 8
    paths.discard("src/slopedist/")
    assert [p for p in sorted(paths) if not (src / p).exists()] == []
    cited = set(re.findall(r"`(src/slopedist/[a-z_/]+(?:\.py)?)`", text))
    assert [p for p in sorted(cited) if not (ROOT / p).exists()] == []
    functions = set(re.findall(r"`(core\.geometry\.[a-z_]+)`", text))
    assert len(functions) >= 5
    assert [f for f in sorted(functions) if not _resolves(f)] == []


def test_the_code_map_of_ours_lists_every_module_once() -> None:
    """docs/method.md's code map of ``ours`` has one row for each of its modules."""
    text = (ROOT / "docs" / "method.md").read_text(encoding="utf-8")
    table = text.split("Code map of\n`src/slopedist/estimators/ours/`", 1)[1].split("\n\n", 2)[1]
    rows = re.findall(r"^\| `([a-z_]+\.py)` \|", table, flags=re.MULTILINE)
    package = ROOT / "src" / "slopedist" / "estimators" / "ours"
    modules = sorted(p.name for p in package.glob("*.py") if p.name != "__init__.py")
    assert sorted(rows) == modules
    assert len(rows) == len(set(rows))


def markdown_table_column(path: Path, heading: str) -> list[str]:
    """The first cells (without backticks) of the first table under ``heading``."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start = lines.index(heading)
    cells: list[str] = []
    for line in lines[start + 1 :]:
        if line.startswith("#"):
            break
        if line.startswith("|"):
            cells.append(line.split("|")[1].strip().strip("`"))
        elif cells:
            break
    return cells[2:]  # after the header and its rule


def test_the_records_schema_table_lists_the_default_columns() -> None:
    """docs/usage.md's table of ``records.csv`` is the code's default column list, in order."""
    from slopedist.streaming.step import DEFAULT_RECORD_FIELDS

    table = markdown_table_column(ROOT / "docs" / "usage.md", "### Columns of `records.csv`")
    assert table == list(DEFAULT_RECORD_FIELDS)
