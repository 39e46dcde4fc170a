"""The declared dependencies match what the code imports: runtime pins (requirements/python.txt,
ros.txt) apart from test pins (test.txt), no unused pin, package.xml's keys for every ROS package
and Python library hopper_ros/ imports, and the README's robot install line."""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
import xml.etree.ElementTree as ElementTree
from functools import lru_cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REQUIREMENTS = REPO / "requirements"
# Python libraries without a rosdep key: the README's robot install line installs them with pip
PIP_ONLY = {"filterpy", "mcap", "zstandard", "lz4"}


def pins(name: str) -> dict[str, dict[str, str]]:
    """{'direct'|'transitive': {normalised distribution: version}} of a requirements file."""
    out = {"direct": {}, "transitive": {}}
    section = "direct"
    for line in (REQUIREMENTS / name).read_text().splitlines():
        if line.startswith("# --- transitive"):
            section = "transitive"
        text = line.split("#", 1)[0].strip()
        if text:
            dist, _, version = text.partition("==")
            assert version, f"{name}: {text!r} is not pinned with =="
            out[section][normalise(dist)] = version
    return out


def normalise(dist: str) -> str:
    return re.sub(r"[-_.]+", "-", dist).lower()


@lru_cache(maxsize=None)
def project_modules() -> frozenset[str]:
    """Names the project's own files and packages import each other by (tests import bench
    helpers, test packages, ...)."""
    names = set()
    for folder in ("test", "bench", "tools"):
        for path in (REPO / folder).rglob("*.py"):
            names.add(path.stem)
            names.update(parent.name for parent in path.relative_to(REPO).parents if parent.name)
    return frozenset(names)


def imported_modules(folder: Path) -> set[str]:
    """Top-level modules imported anywhere under `folder` (also inside functions), but the
    project's own."""
    found = set()
    local = project_modules()
    for path in folder.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - local - {"hopper_ros", "__future__"}


@lru_cache(maxsize=None)
def distributions_of_modules() -> dict[str, set[str]]:
    return {module: {normalise(d) for d in dists} for module, dists in importlib.metadata.packages_distributions().items()}


def distributions(modules: set[str]) -> dict[str, str]:
    """{module: the distribution that provides it} (installed in this environment)."""
    table = distributions_of_modules()
    missing = sorted(m for m in modules if m not in table)
    assert not missing, f"imported but provided by no installed distribution: {missing}"
    # a ROS package's module is provided by its wheel (ros-*) and, here, by the egg-info that its
    # CMake install left beside it: the wheel is what is pinned
    return {module: min(table[module], key=lambda dist: (not dist.startswith("ros-"), dist)) for module in modules}


def runtime_modules() -> dict[str, str]:
    return distributions(imported_modules(REPO / "hopper_ros"))


def test_pin_files_are_apart_and_complete():
    files = {name: pins(name) for name in ("ros.txt", "python.txt", "test.txt")}
    seen: dict[str, str] = {}
    for name, sections in files.items():
        for dist in {**sections["direct"], **sections["transitive"]}:
            assert dist not in seen, f"{dist} is pinned in {seen[dist]} and in {name}"
            seen[dist] = name
    # the environment holds every pin at its version (make setup installed exactly these)
    for dist, name in seen.items():
        version = {**files[name]["direct"], **files[name]["transitive"]}[dist]
        assert importlib.metadata.version(dist) == version, f"{dist} ({name})"


def test_every_runtime_import_is_pinned_for_runtime_and_every_direct_pin_is_used():
    runtime = {**pins("python.txt")["direct"], **pins("python.txt")["transitive"], **pins("ros.txt")["direct"]}
    used = runtime_modules()
    unpinned = {module: dist for module, dist in used.items() if dist not in runtime}
    assert not unpinned, f"hopper_ros imports these, but no runtime pin holds them: {unpinned}"
    test_only = set(pins("test.txt")["direct"]) & set(used.values())
    assert not test_only, f"hopper_ros imports {test_only}, pinned as test tools only"
    direct = set(pins("python.txt")["direct"]) - {"setuptools"}          # setuptools: the build backend
    unused = direct - set(used.values())
    assert not unused, f"python.txt pins {unused} directly, but hopper_ros/ imports none of it"


def test_test_tools_are_what_the_tests_use():
    used = set(distributions(imported_modules(REPO / "test") | imported_modules(REPO / "bench")).values())
    for dist in pins("test.txt")["direct"]:
        assert dist in used, f"test.txt pins {dist}, which no test or benchmark imports"
    assert "mcap-ros2-support" not in {**pins("python.txt")["direct"], **pins("test.txt")["direct"]}


def test_package_xml_lists_what_the_code_imports():
    root = ElementTree.parse(REPO / "package.xml").getroot()
    keys = {element.text.strip() for element in root if element.tag in ("depend", "exec_depend")}
    for module, dist in runtime_modules().items():
        if dist.startswith("ros-"):
            assert module in keys, f"hopper_ros imports {module} (a ROS package): package.xml lacks it"
        elif dist in PIP_ONLY:
            assert f"python3-{module}" not in keys
        else:
            key = {"yaml": "python3-yaml", "can": "python3-can"}.get(module, f"python3-{module}")
            assert key in keys, f"hopper_ros imports {module} ({dist}): package.xml lacks the rosdep key {key}"
    assert "diagnostic_msgs" in keys
    test_keys = {element.text.strip() for element in root if element.tag == "test_depend"}
    assert "python3-pytest" in test_keys and "python3-pytest" not in keys


def test_readme_robot_install_line_installs_the_runtime_libraries_without_keys():
    readme = (REPO / "README.md").read_text()
    [line] = [line for line in readme.splitlines() if line.startswith("pip install ")]
    words = line.split("#", 1)[0].split()[2:]
    packages = [w for w in words if not w.startswith("-")]                     # --user --break-system-packages (PEP 668)
    used = set(runtime_modules().values())
    assert {normalise(p.split("==")[0]) for p in packages} == {"filterpy", "mcap"}   # mcap brings lz4 and zstandard
    pinned = pins("python.txt")["direct"]
    for p in packages:                                                         # the versions of requirements/python.txt
        name, _, version = p.partition("==")
        assert version == pinned[normalise(name)], p
    assert {"lz4", "zstandard"} <= set(normalise(r.split(";")[0].split()[0].split(">")[0].split("=")[0].split("<")[0])
                                       for r in importlib.metadata.requires("mcap"))
    assert PIP_ONLY <= used
    for tool in pins("test.txt")["direct"]:
        assert tool not in line, f"the robot install line installs the test tool {tool}"


def test_setup_install_requires_is_the_runtime_pins():
    """`pip install .` installs what the package imports at the versions make setup pins (issue 31)."""
    namespace = {"__file__": str(REPO / "setup.py")}
    exec((REPO / "setup.py").read_text().split("\nsetup(\n")[0], namespace)
    required = {normalise(r.split("==")[0]): r.split("==")[1] for r in namespace["_runtime_pins"]()}
    expected = {name: version for name, version in pins("python.txt")["direct"].items() if name != "setuptools"}
    assert required == expected
    assert set(runtime_modules().values()) - {"rclpy"} <= set(required) | set(pins("ros.txt")["direct"])
