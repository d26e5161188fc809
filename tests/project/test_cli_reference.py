"""docs/cli.md is what --help gives (tools/cli_reference.py), and every example in it is a
command line the parser takes."""

import importlib.util
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def reference():
    spec = importlib.util.spec_from_file_location("cli_reference",
                                                  ROOT / "tools" / "cli_reference.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_docs_cli_md_is_what_help_gives(reference):
    assert (ROOT / "docs" / "cli.md").read_text() == reference.render(), \
        "docs/cli.md is stale: run python tools/cli_reference.py"


def test_every_command_has_its_section(reference):
    from raplas_hdl.cli import SUBCOMMANDS

    text = (ROOT / "docs" / "cli.md").read_text()
    for name in SUBCOMMANDS:
        assert f"## raplas-hdl {name}\n" in text and f"usage: raplas-hdl {name} " in text


def test_every_example_parses(reference):
    from raplas_hdl.cli import build_parser

    parser = build_parser()
    examples = [e for _, ex in reference.COMMANDS.values() for e in ex]
    assert len(examples) >= len(reference.COMMANDS)
    for line in examples:
        argv = shlex.split(line)
        assert argv[0] == "raplas-hdl"
        args = parser.parse_args(argv[1:])
        assert args.command == argv[1], line


def test_a_stale_reference_is_reported(reference, tmp_path, monkeypatch, capsys):
    stale = tmp_path / "cli.md"
    stale.write_text(reference.render().replace("usage: raplas-hdl pnr", "usage: raplas pnr"))
    monkeypatch.setattr(reference, "DOC", stale)
    assert reference.main(["--check"]) == 1
    assert "docs/cli.md is not what --help gives" in capsys.readouterr().err


def test_the_readme_quick_start_parses():
    from raplas_hdl.cli import build_parser

    text = (ROOT / "README.md").read_text()
    block = text.split("## Quick start", 1)[1].split("```sh", 1)[1].split("```", 1)[0]
    lines = [ln.split("#", 1)[0].strip() for ln in block.strip().splitlines()]
    assert len(lines) == 5
    parser = build_parser()
    for line in lines:
        argv = shlex.split(line)
        assert argv[0] == "raplas-hdl" and parser.parse_args(argv[1:]).command == argv[1]
