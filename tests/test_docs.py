"""The documentation site (``mkdocs.yml``, ``docs/``) and the README that points to it.

The site builds without a single warning, every ``cosim <command>`` (and its options) and every
``cosim.*`` / ``controllers.*`` name that a page or the README names exists, the exit-code
table quoted in the guide is the one the CLI prints, the module map names every module, and
the README stays short.
"""

from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
from functools import cache
from pathlib import Path

import pytest

from cosim.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
#: The README is the front page: what it is, two commands, results, layout, architecture.
README_MAX_BYTES = 10 * 1024


def _pages() -> list[Path]:
    return [*sorted(DOCS.rglob("*.md")), README]


@cache
def _subparsers() -> dict:
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return dict(action.choices)


def _code(text: str) -> list[str]:
    """Fenced code blocks (continuation lines joined) and inline code spans of a page."""
    pieces = []
    for block in re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.S | re.M):
        pieces += block.replace("\\\n", " ").splitlines()
    text = re.sub(r"^```[^\n]*\n.*?^```", "", text, flags=re.S | re.M)
    pieces += re.findall(r"`([^`\n]+)`", text)
    return pieces


def _invocations() -> list[tuple[str, str, str]]:
    """``(page, command, rest of the line)`` for every ``cosim <command>`` in code."""
    found = []
    for page in _pages():
        for piece in _code(page.read_text(encoding="utf-8")):
            for m in re.finditer(r"(?:^|[\s/$(])cosim ([a-z][a-z0-9-]*)([^#|;&]*)", piece):
                found.append((str(page.relative_to(ROOT)), m.group(1), m.group(2)))
    return found


@pytest.mark.slow
def test_the_site_builds_without_a_warning(tmp_path: Path) -> None:
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "index.html").is_file()
    assert (tmp_path / "reference" / "controllers" / "fhocp.html").is_file()


def test_every_cosim_command_named_in_the_docs_exists() -> None:
    commands = _subparsers()
    found = _invocations()
    assert {c for _, c, _ in found} >= {"run", "campaign", "certify", "compare"}, found
    unknown = sorted({(page, c) for page, c, _ in found if c not in commands})
    assert not unknown, f"cosim has no such command (cosim --help): {unknown}"


def test_every_option_of_a_named_command_exists() -> None:
    commands = _subparsers()
    bad = set()
    for page, command, rest in _invocations():
        if command not in commands:
            continue
        known = {s for a in commands[command]._actions for s in a.option_strings}
        for option in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest):
            if option not in known:
                bad.add((page, f"cosim {command} {option}"))
    assert not bad, f"options not in `cosim <command> --help`: {sorted(bad)}"


def test_every_python_name_in_the_docs_exists() -> None:
    """``cosim.x.y`` / ``controllers.x.y`` in a code span: a module, then attributes."""
    names = set()
    for page in _pages():
        for span in re.findall(r"`([^`\n]+)`", page.read_text(encoding="utf-8")):
            for m in re.finditer(r"(?<![\w./-])((?:cosim|controllers)(?:\.[A-Za-z_]\w*)+)",
                                 span):
                names.add((str(page.relative_to(ROOT)), m.group(1)))
    assert len(names) > 50
    missing = []
    for page, name in sorted(names):
        parts = name.split(".")
        for i in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:i]))
            except ImportError:
                continue
            break
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            missing.append((page, name))
    assert not missing, f"names the docs refer to that do not exist: {missing}"


def test_the_quoted_exit_codes_are_those_of_cosim_help() -> None:
    text = (DOCS / "guide" / "running.md").read_text(encoding="utf-8")
    assert build_parser().epilog in text, (
        "docs/guide/running.md quotes an outdated exit-code table: paste the 'exit codes:' "
        "paragraph of `cosim --help` (cosim.core.errors.exit_codes_help)")


def test_the_readme_lists_every_exit_code() -> None:
    from cosim.core.errors import EXIT_CODES, EXIT_SIGNAL_BASE

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text[text.index("## Exit codes"):text.index("## Results at a glance")]
    rows = {line.split("|")[1].strip() for line in table.splitlines() if line.startswith("| ")}
    for code, _meaning in EXIT_CODES:
        label = f"{EXIT_SIGNAL_BASE} + N" if code >= EXIT_SIGNAL_BASE else str(code)
        assert label in rows, f"README.md, section 'Exit codes': no row for exit code {code}"


def test_the_module_map_names_every_module() -> None:
    text = (DOCS / "design" / "architecture.md").read_text(encoding="utf-8")
    missing = []
    for package in ("controllers", "cosim"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name == "__init__.py":
                continue
            module = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            if f"`{module}`" not in text:
                missing.append(module)
    assert not missing, f"docs/design/architecture.md, module map: add {missing}"


def test_the_readme_is_short() -> None:
    size = README.stat().st_size
    assert size <= README_MAX_BYTES, (
        f"README.md is {size} bytes (at most {README_MAX_BYTES}): move the detail to docs/")


def test_the_controller_fmu_page_runs_as_written(tmp_path: Path, fmu2_path: Path) -> None:
    """docs/guide/controller-fmu.md end to end: its ``cosim export-fmu`` line, then its fmpy
    loop of plant and controller FMUs, which tracks the set-points it names."""
    text = (DOCS / "guide" / "controller-fmu.md").read_text(encoding="utf-8")
    shell = re.search(r"^```sh\n(.*?)^```", text, flags=re.S | re.M)
    python = re.search(r"^```python\n(.*?)^```", text, flags=re.S | re.M)
    assert shell and python
    export = next(line for line in shell.group(1).splitlines()
                  if line.startswith("cosim export-fmu --out Controller.fmu"))
    (tmp_path / "fmus").mkdir()
    (tmp_path / "fmus" / "FourTank.fmu").write_bytes(fmu2_path.read_bytes())
    cosim_bin = Path(sys.executable).with_name("cosim")
    args = export.split("#")[0].split()[1:]
    proc = subprocess.run([str(cosim_bin), *args], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    script = tmp_path / "loop.py"
    script.write_text(python.group(1))
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    h1, h2 = (float(v) for v in re.findall(r"h\d = ([0-9.]+) m", proc.stdout))
    assert abs(h1 - 1.3) < 0.02 and abs(h2 - 1.4) < 0.02, proc.stdout
