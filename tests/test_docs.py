"""README and docs a newcomer can copy: their examples on the sample meshes run as written
from the checkout, the extras list is complete, ``--help`` keeps an example command on one
line, ``merge``'s formats are the ones it joins, and shell completion is there."""

import re
import shlex
import sys
import tomllib

import pytest
from click.testing import CliRunner

from scatter_cli import cli
from scatter_cli.writers.formats import MERGEABLE

from .conftest import ROOT, run_user

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


# -- the examples run as written -------------------------------------------------------------

def code_blocks(text):
    """The shell blocks of a Markdown text: indented by four spaces or fenced (not Python),
    each a list of commands (lines joined at a trailing backslash, comments and blank lines
    left out)."""
    blocks, block, fenced = [], [], None
    for line in text.splitlines() + [""]:
        if line.startswith("```"):
            fenced = None if fenced is not None else line[3:].strip()
            blocks.append(block)
            block = []
        elif fenced is not None:
            block.append(line) if fenced not in ("python", "py", "toml", "json", "text") else None
        elif line.startswith("    ") and not line.lstrip().startswith("- "):
            block.append(line[4:])
        elif line.strip():
            blocks.append(block)
            block = []
    commands = []
    for lines in blocks:
        joined = re.sub(r"\\\n\s*", "", "\n".join(lines))
        commands.append([c for c in joined.splitlines() if c.strip() and not c.lstrip().startswith("#")])
    return [c for c in commands if c]


def examples_on_samples(text):
    """The commands of the blocks that use the sample meshes (``samples/``), in order, but
    the set-up lines (a virtual environment, pip): they build the checkout, not use it."""
    return [c for block in code_blocks(text) if any("samples/" in c for c in block)
            for c in block if not c.startswith(("python3 -m venv", "pip "))]


def failures(commands, folder):
    """[(command, its error output)] of the ``commands`` that fail when a shell runs them in
    order in ``folder`` (which holds the checkout's ``samples``), with ``scatter`` this tree's
    command: one shell for all of them."""
    (folder / "samples").symlink_to(ROOT / "samples")
    script = [f"scatter() {{ {shlex.quote(sys.executable)} -m scatter_cli \"$@\"; }}"]
    for k, command in enumerate(commands):
        script.append(f"{{ {command}\n}} >/dev/null 2>err-{k}.txt; echo $? >rc-{k}.txt")
    run_user(["bash", "-c", "\n".join(script)], cwd=folder, timeout=600)
    return [(c, (folder / f"err-{k}.txt").read_text()) for k, c in enumerate(commands)
            if (folder / f"rc-{k}.txt").read_text().strip() != "0"]


BROKEN = """
    scatter sample samples/no-such-mesh.ply -n 10 -o a.ply
    scatter sample samples/skull.ply -n 10 -o not-made/a.ply
"""


@pytest.mark.slow
def test_the_examples_on_the_sample_meshes_run_as_written(tmp_path):
    commands = [c for doc in DOCS for c in examples_on_samples(doc.read_text())]
    assert len(commands) >= 10 and any(c.startswith("scatter batch samples/") for c in commands)
    assert not any(".venv" in c for c in commands)  # the first two commands of the README stay out
    broken = examples_on_samples(BROKEN)  # the broken variant: a missing mesh, a folder not made first
    failed = failures(commands + broken, tmp_path)
    assert [c for c, _ in failed] == broken, failed


def test_the_examples_are_found_in_indented_and_fenced_blocks():
    text = ("Intro\n\n    scatter info samples/a.ply   # a comment\n    scatter sample samples/a.ply \\\n"
            "        -n 5 -o b.ply\n\n```sh\nscatter info samples/c.ply\n```\n\n```python\nx = 'samples/d.ply'\n```\n"
            "\n    scatter info other.ply\n")
    assert examples_on_samples(text) == ["scatter info samples/a.ply   # a comment",
                                         "scatter sample samples/a.ply -n 5 -o b.ply", "scatter info samples/c.ply"]


# -- the extras, merge's formats ---------------------------------------------------------------

def listed_extras(readme):
    """The extras of the README's ``pip install '.[...]'``."""
    return set(re.search(r"pip install '\.\[([a-z,]+)\]'", readme).group(1).split(","))


def test_the_readme_lists_every_extra():
    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]) - {"test"}
    readme = (ROOT / "README.md").read_text()
    assert listed_extras(readme) == extras
    assert listed_extras(readme.replace("texture,", "")) != extras  # the broken variant: the list without texture


def merge_formats(text):
    """The formats a sentence saying what ``scatter merge`` joins names (upper case words)."""
    sentence = re.search(r"`scatter merge` joins ([^;]*)", " ".join(text.split())).group(1)
    return {w.lower() for w in re.findall(r"\b[A-Z]{3}\b", sentence)} - {"not", "usd"}


def test_merge_formats_are_the_ones_it_joins():
    assert merge_formats((ROOT / "docs" / "batch.md").read_text()) == set(MERGEABLE)
    assert merge_formats("`scatter merge` joins PLY (binary and ASCII), CSV, XYZ and NPY; parts") != set(MERGEABLE)
    help_text = " ".join(CliRunner().invoke(cli.command(), ["merge", "--help"], terminal_width=80).output.split())
    assert f"({', '.join(MERGEABLE)})" in help_text


# -- --help keeps an example on one line ---------------------------------------------------------

def unwrapped(command_names):
    """[(command, example)] of the example commands of the docstrings of ``command_names``
    ("": ``scatter`` itself) that ``--help`` (80 columns) does not print whole on one line."""
    root = cli.command()
    missing = []
    for name in command_names:
        cmd = root.commands[name] if name else root
        examples = [line.strip() for line in (cmd.help or "").splitlines() if line.strip().startswith("scatter ")]
        printed = CliRunner().invoke(root, [name, "--help"] if name else ["--help"], terminal_width=80).output
        missing += [(name, e) for e in examples if e not in [line.strip() for line in printed.splitlines()]]
    return missing


def test_help_examples_are_not_rewrapped(monkeypatch):
    names = ["", *cli.command().commands]
    assert unwrapped(names) == []
    monkeypatch.setattr(cli, "examples_kept", lambda text: text)  # the broken variant: click re-wraps them
    assert ("sample", "scatter sample chair.obj --normalize unit-sphere --near 0.0707,0.0224 --box-share 0.06 "
            "-n 250000 -a sdf -o chair.npy") in unwrapped(names)


# -- shell completion ----------------------------------------------------------------------------

def completion(*args, env=None):
    """(exit code, output) of ``scatter ARGS`` run in-process as the command line runs it."""
    result = CliRunner().invoke(cli.command(), cli.shell_named(args), prog_name="scatter", env=env)
    return result.exit_code, result.output


SCRIPTS = {"bash": "complete -o default -F _scatter_completion scatter", "zsh": "#compdef scatter",
           "fish": "complete --command scatter"}


def assert_completion(home):
    for shell, line in SCRIPTS.items():
        code, text = completion("--show-completion", shell)
        assert code == 0 and line in text, (shell, text)
    code, text = completion("--show-completion", "tcsh")
    assert code == 2 and "tcsh" in text
    code, text = completion("--install-completion", "bash", env={"HOME": str(home)})
    assert code == 0 and (home / ".bash_completions" / "scatter.sh").read_text().strip().endswith(SCRIPTS["bash"])
    # what the installed script asks for: the commands that complete "sa"
    code, text = completion(env={"_SCATTER_COMPLETE": "complete_bash", "COMP_WORDS": "scatter sa", "COMP_CWORD": "1"})
    assert text.split() == ["sample"]


def test_shell_completion(tmp_path, monkeypatch):
    assert_completion(tmp_path)
    # alone: the shell detected (from this process's ancestors, which a test run started
    # without a shell lacks: the user's shell here), the rest parsed as ever
    import shellingham

    monkeypatch.setattr(shellingham, "detect_shell", lambda *args, **kwargs: ("zsh", "/bin/zsh"))
    code, text = completion("--show-completion", "--debug")
    assert code == 0 and SCRIPTS["zsh"] in text, text
    monkeypatch.setattr(cli, "completion_option", lambda option: option)  # the broken variant: typer's flags
    with pytest.raises(AssertionError):
        assert_completion(tmp_path / "broken")
