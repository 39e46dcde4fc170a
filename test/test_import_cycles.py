"""No import cycle between hopper_ros's modules, type-checking imports included (issue 30):
tools/import_cycles.py reads the imports with `ast` and reports every cycle."""

from __future__ import annotations

import subprocess
import sys

from conftest import REPO

TOOL = REPO / "tools" / "import_cycles.py"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(TOOL), *args], capture_output=True, text=True, timeout=120)


def test_hopper_ros_has_no_import_cycle():
    result = _run()
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.strip() == "no import cycle"


def test_the_tool_finds_a_cycle_of_type_checking_and_relative_imports(tmp_path):
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("")
    (package / "a.py").write_text("from pkg.sub import b\n")
    (package / "sub" / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .. import c\n")
    (package / "c.py").write_text("def f():\n    from pkg import a\n")
    assert _run(str(package)).returncode == 0                 # c imports a only inside a function
    result = _run(str(package), "--lazy")
    assert result.returncode == 1
    assert result.stdout.strip() == "import cycle: pkg.a -> pkg.sub.b -> pkg.c -> pkg.a"
