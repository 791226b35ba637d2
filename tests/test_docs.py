"""Every command in the README and the docs site runs in a test.

Shell blocks (```bash / sh / console) are split into commands. `mavtune ...` commands that are cheap on the simulator
run for real, in document order, in one folder per page (a command may use what an earlier one made); long ones run
under `-m slow` and are parsed by the CLI meanwhile; the ones that need SITL, hardware, a Zenoh swarm or a Dask
cluster are parsed by the CLI without running. TOML blocks are validated by the config models (a block titled
`title="x.toml"` is written to the page's folder first, for the commands that read it); Python blocks run.
`mkdocs build --strict` must succeed.
"""

from __future__ import annotations

import importlib
import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
import typer
from markdown_it import MarkdownIt

click = importlib.import_module(typer.BadParameter.__module__.rsplit(".", 1)[0])  # the click typer runs on

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL = {"bash", "sh", "console", "shell"}

# Tools the docs name that belong to other projects (ArduPilot's SITL, Dask's cluster): not run here.
EXTERNAL = {"arducopter", "sim_vehicle.py", "dask"}
# mavtune commands that need something outside this machine's test run (a swarm, a vehicle, a cluster) or serve
# forever: parsed, never run.
OUTSIDE_COMMANDS = {"agent", "coordinator", "mavsim", "swarm-key", "restore"}
OUTSIDE_FLEETS = {"mavlink", "zenoh"}
# mavtune commands too long for the default suite (> ~20 s): run under -m slow.
LONG_COMMANDS = {"reproduce", "bench"}


@dataclass(frozen=True)
class Block:
    """A fenced block of a page."""

    page: Path
    line: int  # 1-based, the fence's
    lang: str
    title: str | None
    text: str


@dataclass(frozen=True)
class Command:
    """One command of a shell block."""

    page: Path
    line: int
    argv: tuple[str, ...]

    @property
    def id(self) -> str:
        return f"{self.page.name}:{self.line}:{' '.join(self.argv)[:60]}"


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a markdown page, with their language and `title="..."` if any."""
    found = []
    for token in MarkdownIt().parse(page.read_text()):
        if token.type != "fence":
            continue
        lang, _, rest = token.info.strip().partition(" ")
        title = re.search(r'title="([^"]+)"', rest)
        found.append(Block(page, token.map[0] + 1, lang, title.group(1) if title else None, token.content))
    return found


def commands(block: Block) -> list[Command]:
    """The commands of a shell block: comments dropped, `\\` continuations joined, split at `&&`, `;` and `&`."""
    found = []
    text = block.text.replace("\\\n", " ")
    for offset, line in enumerate(text.splitlines()):
        line = line.strip()
        if line.startswith("$ "):
            line = line[2:]
        lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
        lexer.whitespace_split = True
        argv: list[str] = []
        for word in [*lexer, ";"]:
            if word in (";", "&", "&&", "|", "||"):
                if argv:
                    found.append(Command(block.page, block.line + 1 + offset, tuple(argv)))
                argv = []
            else:
                argv.append(word)
    return found


def all_blocks() -> list[Block]:
    return [b for page in PAGES for b in blocks(page)]


def page_commands(page: Path) -> list[Command]:
    return [c for b in blocks(page) if b.lang in SHELL for c in commands(b)]


def all_commands() -> list[Command]:
    """Every command of every page; a command a page repeats from an earlier one (the README's two on the home
    page) is checked once, unless it reads or writes a folder its page's other commands use."""
    found, seen = [], set()
    for page in PAGES:
        for command in page_commands(page):
            shared = any(word in ("--out", "-o", "-c", "--config") for word in command.argv) or \
                command.argv[1:2] in (("report",), ("bank",))
            if command.argv not in seen or shared:
                found.append(command)
            seen.add(command.argv)
    return found


def _option(argv: tuple[str, ...], *names: str) -> str | None:
    """The value of an option (`--fleet x` or `--fleet=x`), or None."""
    for i, word in enumerate(argv):
        for name in names:
            if word == name and i + 1 < len(argv):
                return argv[i + 1]
            if word.startswith(name + "="):
                return word.split("=", 1)[1]
    return None


def _file_fleet(folder: Path, argv: tuple[str, ...]) -> str:
    """The fleet kind a `-c FILE` sets, if the file is there (written from a titled block of the page)."""
    config = _option(argv, "-c", "--config")
    if config is None or not (folder / config).is_file():
        return "sim"
    return tomllib.loads((folder / config).read_text()).get("fleet", {}).get("kind", "sim")


def kind(command: Command, folder: Path) -> str:
    """How a mavtune command is checked: "run" (for real), "long" (for real under -m slow) or "parse"."""
    argv = command.argv
    sub = argv[1] if len(argv) > 1 else ""
    fleet = _option(argv, "--fleet") or _file_fleet(folder, argv)
    if sub in OUTSIDE_COMMANDS or fleet in OUTSIDE_FLEETS or _option(argv, "--scheduler") is not None:
        return "parse"
    if sub in LONG_COMMANDS or argv[1:3] == ("bank", "build"):
        return "long"
    if sub == "surface":
        grid, repeats = int(_option(argv, "--grid") or 25), int(_option(argv, "--repeats") or 20)
        return "long" if grid * grid * repeats > 1000 else "run"
    return "run"


def parse(argv: tuple[str, ...]):
    """Parse a `mavtune` command line with the CLI's own commands, without running it (types, choices, required);
    the click context of the command, or None for an option that answers at once (`--version`)."""
    from mavtune.cli import app

    command = typer.main.get_command(app)
    try:
        ctx = command.make_context("mavtune", list(argv[1:]))
    except typer.Exit:
        return None
    while hasattr(command, "resolve_command"):  # a group: its subcommand parses next
        protected = getattr(ctx, "_protected_args", None) or getattr(ctx, "protected_args", None) or []
        rest = [*protected, *ctx.args]
        name, command, rest = command.resolve_command(ctx, rest)
        assert command is not None, f"unknown command {name!r} in {' '.join(argv)}"
        ctx = command.make_context(name, rest, parent=ctx)
    return ctx


def run(argv: tuple[str, ...], folder: Path) -> subprocess.CompletedProcess:
    """Run a mavtune command in `folder`, as a user would (a fresh process)."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)  # this tree's mavtune
    env = {**os.environ, "PYTHONPATH": path, "COLUMNS": "120"}
    return subprocess.run([sys.executable, "-m", "mavtune", *argv[1:]], cwd=folder, env=env, capture_output=True,
                          text=True, timeout=600, stdin=subprocess.DEVNULL)


def check_other(command: Command) -> None:
    """A command that is not mavtune's: what it names must exist (an extra, a benchmark, a marker)."""
    argv = command.argv
    if argv[0] in EXTERNAL:
        return
    if argv[:2] == ("pip", "install"):
        extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
        for word in argv[2:]:
            for extra in re.findall(r"\.\[([a-z,]+)\]", word):
                assert set(extra.split(",")) <= set(extras), f"{command.id}: no extra {extra!r} in pyproject.toml"
        return
    if argv[0] == "pytest":
        markers = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["markers"]
        names = {m.split(":")[0] for m in markers}
        marker = _option(argv, "-m")
        assert marker is None or marker.replace("not ", "") in names, f"{command.id}: unknown marker {marker}"
        for word in argv[1:]:
            if word.startswith("tests/"):
                assert (ROOT / word.split("::")[0]).exists(), f"{command.id}: {word} does not exist"
        return
    if argv[0] == "python" and len(argv) > 1 and argv[1].startswith("benchmarks/"):
        assert (ROOT / argv[1]).is_file(), f"{command.id}: {argv[1]} does not exist"
        return
    if argv[0] == "mkdocs":
        assert argv[1] in ("build", "serve"), f"{command.id}: mkdocs {argv[1]}?"  # build: test_mkdocs_build
        return
    raise AssertionError(f"{command.id}: tests/test_docs.py does not know how to check this command")


class Page:
    """A page's commands run in document order in one folder, each at most once per session."""

    def __init__(self, page: Path, folder: Path):
        self.page, self.folder, self.done = page, folder, 0
        self.commands = page_commands(page)
        folder.mkdir(parents=True, exist_ok=True)
        for block in blocks(page):
            if block.title:
                (folder / block.title).write_text(block.text)

    def through(self, command: Command, long: bool) -> None:
        """Run the page's commands up to and including `command` (long ones only when `long`); a command checked on
        an earlier page is not run again here."""
        index = self.commands.index(command)
        while self.done <= index:
            if self.done == index or self.commands[self.done] in COMMANDS:
                self.one(self.commands[self.done], long)
            self.done += 1

    def one(self, command: Command, long: bool) -> None:
        if command.argv[0] != "mavtune":
            check_other(command)
            return
        parse(command.argv)  # every mavtune command parses
        how = kind(command, self.folder)
        if how == "run" or (how == "long" and long):
            done = run(command.argv, self.folder)
            assert done.returncode == 0, (f"{command.id} failed with status {done.returncode}:\n"
                                          f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}")


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    made: dict[tuple[Path, bool], Page] = {}

    def get(page: Path, long: bool) -> Page:
        if (page, long) not in made:
            made[page, long] = Page(page, tmp_path_factory.mktemp(page.stem + ("-long" if long else "")))
        return made[page, long]

    return get


COMMANDS = all_commands()


@pytest.mark.parametrize("command", COMMANDS, ids=[c.id for c in COMMANDS])
def test_command(command, pages):
    """Each command of the docs: run (cheap simulator runs), parsed (the rest), or checked to exist."""
    pages(command.page, False).through(command, long=False)


LONG = [c for c in COMMANDS if c.argv[0] == "mavtune" and kind(c, Path("/nonexistent")) == "long"]


@pytest.mark.slow
@pytest.mark.parametrize("command", LONG, ids=[c.id for c in LONG])
def test_long_command(command, pages):
    """The long commands of the docs, run for real (with everything their page runs before them)."""
    pages(command.page, True).through(command, long=True)


def test_docs_have_commands_of_every_kind(tmp_path):
    """The classification is not vacuous: some commands run, some only parse, some are long."""
    kinds = {kind(c, tmp_path) for c in COMMANDS if c.argv[0] == "mavtune"}
    assert kinds == {"run", "parse", "long"}


def test_parse_rejects_a_bad_flag():
    """The parse-only check can fail: a flag the CLI lacks, or a bad value, is an error."""
    with pytest.raises(click.exceptions.UsageError):
        parse(("mavtune", "tune", "--no-such-flag"))
    with pytest.raises(click.exceptions.BadParameter):
        parse(("mavtune", "agent", "--id", "v0", "--seed", "many"))
    assert parse(("mavtune", "bank", "lookup", "bank.json", "--mass-kg", "2.5")).params["mass_kg"] == 2.5


PY_BLOCKS = [b for b in all_blocks() if b.lang == "python"]


@pytest.mark.parametrize("block", PY_BLOCKS, ids=[f"{b.page.name}:{b.line}" for b in PY_BLOCKS])
def test_python_block(block, tmp_path, monkeypatch):
    """Each Python block of the docs runs as written."""
    monkeypatch.chdir(tmp_path)
    exec(compile(block.text, f"{block.page.name}:{block.line}", "exec"), {"__name__": "__docs__"})


TOML_BLOCKS = [b for b in all_blocks() if b.lang == "toml"]


@pytest.mark.parametrize("block", TOML_BLOCKS, ids=[f"{b.page.name}:{b.line}" for b in TOML_BLOCKS])
def test_toml_block(block, tmp_path):
    """Each TOML example is a valid config: the run's tables, and [swarm] / [mavlink] by their own models."""
    from mavtune.config import load_config
    from mavtune.swarm.config import load_swarm_config
    from mavtune.vehicles.mavlink.config import load_mavlink_config

    path = tmp_path / (block.title or "example.toml")
    path.write_text(block.text)
    data = tomllib.loads(block.text)
    load_config(path)
    if "swarm" in data:
        load_swarm_config(path)
    if "mavlink" in data:
        load_mavlink_config(path)


def test_readme_commands_are_the_ones_ci_runs():
    """The README's two commands (and the home page's), exactly: install and tune, then the test command `.ci/run`
    runs."""
    for page in (ROOT / "README.md", ROOT / "docs" / "index.md"):
        first = next(b for b in blocks(page) if b.lang in SHELL)
        assert first.text == "pip install -e '.[test]' && mavtune tune\npytest\n", page.name
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pip install --quiet -e '.[test]'" in ci
    assert re.search(r"^pytest$", ci, re.M)
    assert re.search(r"^mkdocs build --strict$", ci, re.M)


def test_readme_is_short_and_its_links_resolve():
    """The README is one or two screens, and every local link or image in it exists."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 60
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not re.match(r"[a-z]+://", target):
            assert (ROOT / target).exists(), f"README links to {target}, which does not exist"
    assert re.search(r"!\[[^\]]+\]\(docs/img/[^)]+\.png\)", text), "the README shows a figure"


def test_mkdocs_build_strict(tmp_path):
    """The site builds with no warning (broken links, anchors, nav)."""
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    html = (tmp_path / "site" / "configuration" / "index.html").read_text()
    assert "max_altitude_error_m" in html and "<!-- generated" not in html
    assert "Measured:" in (tmp_path / "site" / "benchmarks" / "index.html").read_text()


def test_config_reference_covers_every_field_and_flag():
    """The generated reference names every field of every table, and each flag it names is `mavtune tune`'s."""
    from docsite import config_reference

    text = config_reference.markdown()
    flags = config_reference.tune_flags()
    for table in config_reference.tables():
        assert f"## `[{table.name}]`" in text
        for name in table.model.model_fields:
            assert name in table.skip or f"| `{name}` |" in text, f"[{table.name}] {name} is missing"
    for dotted, flag in config_reference.FLAGS.items():
        table, name = dotted.rsplit(".", 1)
        model = next(t.model for t in config_reference.tables() if t.name == table)
        assert name in model.model_fields and flag in flags, dotted


def test_benchmarks_page_says_not_recorded_where_a_result_does_not_say(tmp_path):
    """A result's date and machine come from its files; a file that records neither is "not recorded"."""
    from docsite import benchmarks_page

    (tmp_path / "a.md").write_text("# A\n\n`python benchmarks/a.py`, 2026-01-02 03:04 UTC, 8 cores.\n\n"
                                   "| x |\n| - |\n| 1 |\n")
    (tmp_path / "b.md").write_text("# B\n\nno provenance here; ![the map](b/surface.png), [raw](b.json), "
                                   "[paper](https://example.org/p)\n")
    (tmp_path / "b.json").write_text('{"info": {"started_utc": "2026-02-03T04:05:06Z", "cpu_model": "EPYC 9654"}}')
    (tmp_path / "c.json").write_text('{"x": 1}')
    found = {r.name: r for r in benchmarks_page.results(tmp_path)}
    assert found["a"].provenance == benchmarks_page.Provenance("2026-01-02 03:04 UTC", "8 CPUs")
    assert found["b"].provenance == benchmarks_page.Provenance("2026-02-03 04:05 UTC", "EPYC 9654")
    assert found["c"].provenance == benchmarks_page.Provenance("not recorded", "not recorded")
    text = benchmarks_page.markdown(tmp_path)
    assert "| 1 |" in text and "not recorded" in text
    folder = tmp_path.name  # links into the repository become paths (the site could not resolve them); web links stay
    assert f"(figure: `benchmarks/{folder}/b/surface.png`)" in text and f"raw (`benchmarks/{folder}/b.json`)" in text
    assert "[paper](https://example.org/p)" in text


def test_how_it_works_round_counts_are_the_plans(tmp_path):
    """The paper's round counts the page quotes (56 avg, 28 split, no reuse) are what `mavtune plan` says."""
    paper = next(b for b in blocks(ROOT / "docs" / "how-it-works.md") if b.title == "paper.toml")
    (tmp_path / "paper.toml").write_text(paper.text)
    for flags, rounds in (((), 56), (("--strategy", "split"), 28)):
        done = run(("mavtune", "plan", "-c", "paper.toml", *flags), tmp_path)
        assert done.returncode == 0 and re.search(rf"rounds\s+{rounds}\b", done.stdout), done.stdout
    text = (ROOT / "docs" / "how-it-works.md").read_text()
    assert "56 rounds for avg and 28 for split without reuse" in text


def test_every_command_has_an_example():
    """Each `mavtune` command (and bank subcommand) appears in at least one documented command line."""
    from mavtune.cli import LAZY, app, bank_app

    names = {c.name or c.callback.__name__ for c in app.registered_commands} | set(LAZY)
    shown = {c.argv[1] for c in COMMANDS if c.argv[0] == "mavtune" and len(c.argv) > 1}
    assert names <= shown, f"no example of: {', '.join(sorted(names - shown))}"
    banked = {c.argv[2] for c in COMMANDS if c.argv[:2] == ("mavtune", "bank") and len(c.argv) > 2}
    assert {c.name for c in bank_app.registered_commands} <= banked


def test_every_benchmark_script_is_listed():
    """development.md's table names every script in benchmarks/ (common.py is their shared helper)."""
    text = (ROOT / "docs" / "development.md").read_text()
    missing = [p.name for p in sorted((ROOT / "benchmarks").glob("*.py"))
               if p.name != "common.py" and f"`benchmarks/{p.name}`" not in text]
    assert not missing, f"docs/development.md does not list {', '.join(missing)}"
