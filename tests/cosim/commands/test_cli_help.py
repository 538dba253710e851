"""``--help``: the exit codes of every command come from one table (cosim.core.errors)."""

from __future__ import annotations

import pytest

from cosim.cli import COMMANDS, main
from cosim.core.errors import EXIT_CODES, exit_codes_help


def help_text(capsys: pytest.CaptureFixture, *args: str) -> str:
    with pytest.raises(SystemExit):
        main([*args, "--help"])
    return capsys.readouterr().out


def test_every_help_lists_every_exit_code_from_the_table(capsys: pytest.CaptureFixture) -> None:
    commands = [m.rsplit(".", 1)[1].replace("_", "-") for m in COMMANDS]
    assert {"run", "compare", "certify", "campaign"} <= set(commands)
    generic = exit_codes_help().splitlines()
    for args in ([], *([c] for c in commands)):
        text = help_text(capsys, *args)
        assert text.count("exit codes:") == 1, args
        for line in generic:
            assert line in text, (args, line)


def test_commands_add_their_own_meanings(capsys: pytest.CaptureFixture) -> None:
    compare = help_text(capsys, "compare")
    assert "       compare: at least one signal outside the band" in compare
    assert "certify:" not in compare
    top = help_text(capsys)
    for note in ("compare: at least one signal outside the band",
                 "certify: usable but not certified", "campaign: some runs failed"):
        assert note in top


def test_rendering() -> None:
    text = exit_codes_help({"x": {1: "a note " * 20}}, width=60)
    lines = text.splitlines()
    assert lines[0] == "exit codes:" and len(lines) > 1 + len(EXIT_CODES)
    assert all(len(line) <= 60 for line in lines)
    assert lines[1] == "  0    success"
    assert any(line.startswith("       x: a note") for line in lines)
