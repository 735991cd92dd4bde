"""Checks that a package's package.xml declares what its Python code imports, that its
setup.py installs what its source holds from inside the package only, and that the install
is complete. Every ament_python package of the workspace runs them from its
test/test_package_xml.py (``colcon test``); the repository's test/test_packaging.py runs
them against the repository's install/.

Import names are ROS package names, except the Python libraries of ``PYTHON_KEYS``, which
are declared by their rosdep key. A new third-party import fails here until package.xml
declares it (and, for a Python library, until ``PYTHON_KEYS`` names its key).
"""

import ast
import glob
import importlib
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

#: Python import name -> the rosdep keys that may declare it. Keys are those of rosdistro's
#: rosdep/python.yaml; ``*-pip`` marks a library that has no key there (rosdep's pip
#: convention: the rule goes into a local rosdep source).
PYTHON_KEYS = {
    "numpy": {"python3-numpy"},
    "yaml": {"python3-yaml"},
    "matplotlib": {"python3-matplotlib"},
    "PIL": {"python3-pil"},
    "tqdm": {"python3-tqdm"},
    "numba": {"python3-numba"},
    "pytest": {"python3-pytest"},
    "mcap": {"python3-mcap-pip"},
    "rosbags": {"python3-rosbags-pip"},
    "gymnasium": {"python3-gymnasium-pip", "python3-gymnasium"},
    "optuna": {"python3-optuna-pip", "python3-optuna"},
    "minigrid": {"python3-minigrid-pip"},
    "gymnasium_robotics": {"python3-gymnasium-robotics-pip"},
    "farama_notifications": {"python3-farama-notifications-pip"},
    "mujoco": {"python3-mujoco-pip"},
}

#: Top-level directories of a package that are not installed data.
NOT_DATA = {"test", "resource", "__pycache__", "build", "install", "log"}


def package_xml(pkg_dir):
    """(name, {dependency tag: set of names}) of ``pkg_dir/package.xml``."""
    root = ET.parse(pkg_dir / "package.xml").getroot()
    deps = {}
    for tag in ("depend", "exec_depend", "build_depend", "build_export_depend",
                "buildtool_depend", "test_depend"):
        deps[tag] = {e.text.strip() for e in root.findall(tag)}
    return root.findtext("name").strip(), deps


def python_files(*dirs):
    for d in dirs:
        for path in sorted(Path(d).rglob("*.py")):
            if "__pycache__" not in path.parts:
                yield path


def imports(files, pkg_dir):
    """{top-level module: ['file:line', ...]} of every absolute import, lazy ones included."""
    found = {}
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                where = f"{path.relative_to(pkg_dir.parent)}:{node.lineno}"
                found.setdefault(name.split(".")[0], []).append(where)
    return found


def undeclared(found, declared, own):
    missing = {}
    for module, where in sorted(found.items()):
        if module in sys.stdlib_module_names or module == own:
            continue
        keys = PYTHON_KEYS.get(module, {module})
        if not keys & declared:
            missing[" or ".join(sorted(keys))] = where[:3]
    return missing


def runtime_files(pkg_dir, name):
    launch = pkg_dir / "launch"
    return list(python_files(pkg_dir / name, *([launch] if launch.is_dir() else [])))


def check_runtime_imports_are_exec_depends(pkg_dir):
    name, deps = package_xml(pkg_dir)
    found = imports(runtime_files(pkg_dir, name), pkg_dir)
    missing = undeclared(found, deps["exec_depend"] | deps["depend"], name)
    assert not missing, (
        f"{name}/package.xml lacks <exec_depend> for these imports "
        f"(a Python library also needs its rosdep key in PYTHON_KEYS): {missing}")


def check_test_imports_are_declared(pkg_dir):
    name, deps = package_xml(pkg_dir)
    declared = deps["test_depend"] | deps["exec_depend"] | deps["depend"]
    missing = undeclared(imports(python_files(pkg_dir / "test"), pkg_dir), declared, name)
    assert not missing, f"{name}/package.xml lacks <test_depend> for: {missing}"


def check_declared_python_libraries_are_imported(pkg_dir):
    """A rosdep key of a Python library that nothing imports any more is a stale pin."""
    name, deps = package_xml(pkg_dir)
    used = set(imports(runtime_files(pkg_dir, name), pkg_dir))
    stale = sorted(key for module, keys in PYTHON_KEYS.items() for key in keys
                   if key in deps["exec_depend"] | deps["depend"] and module not in used)
    assert not stale, f"{name}/package.xml declares Python libraries it never imports: {stale}"


def check_every_module_imports(pkg_dir):
    """Each module imports: its dependencies are there and no name it imports has gone."""
    name, _ = package_xml(pkg_dir)
    failed = []
    for path in python_files(pkg_dir / name):
        parts = list(path.relative_to(pkg_dir).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        try:
            importlib.import_module(".".join(parts))
        except Exception as exc:  # noqa: BLE001 - report every failing module at once
            failed.append(f"{'.'.join(parts)}: {type(exc).__name__}: {exc}")
    assert not failed, "\n".join(failed)


def check_setup_py_stays_inside_the_package(pkg_dir):
    """setup.py names no file outside its package directory."""
    tree = ast.parse((pkg_dir / "setup.py").read_text(encoding="utf-8"))
    outside = [
        f"setup.py:{n.lineno}: {n.value!r}" for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str)
        and ".." in Path(n.value).parts
    ]
    outside += [f"setup.py:{n.lineno}: {n.attr}" for n in ast.walk(tree)
                if isinstance(n, ast.Attribute) and n.attr in ("pardir", "parent", "parents")]
    assert not outside, outside


def _installed_prefix(name):
    """The install prefix of this package in AMENT_PREFIX_PATH (what ament_index_python's
    get_package_prefix answers); a package not built fails the check."""
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        prefix = Path(prefix)
        index = prefix / "share/ament_index/resource_index/packages"
        if prefix.parts and (index / name).is_file():
            assert (prefix / "share" / name / "package.xml").is_file(), \
                f"{name} found in {prefix}, but without share/{name}/package.xml"
            return prefix
    raise AssertionError(f"{name} is not installed in AMENT_PREFIX_PATH (colcon build first)")


def check_install_holds_the_source_packages_and_data(pkg_dir):
    """Every Python package of the source tree and every data file is installed
    (a subpackage without __init__.py is left out by find_packages)."""
    name, _ = package_xml(pkg_dir)
    prefix = _installed_prefix(name)
    site = glob.glob(str(prefix / "lib" / "python3*" / "site-packages" / name))
    assert site, f"{name} has no site-packages directory under {prefix}"
    site = Path(site[0])
    missing = []
    for path in python_files(pkg_dir / name):
        rel = path.relative_to(pkg_dir / name)
        if not (site / rel).is_file():
            missing.append(f"lib/.../site-packages/{name}/{rel}")
    share = prefix / "share" / name
    expected = [Path("package.xml")]
    for top in sorted(pkg_dir.iterdir()):
        if top.is_dir() and top.name not in NOT_DATA | {name} and not top.name.startswith("."):
            expected += [p.relative_to(pkg_dir) for p in sorted(top.rglob("*"))
                         if p.is_file() and "__pycache__" not in p.parts]
    missing += [f"share/{name}/{rel}" for rel in expected if not (share / rel).is_file()]
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / name
    if not marker.is_file():
        missing.append(str(marker.relative_to(prefix)))
    assert not missing, (f"{name}: not in the install (a stale build? colcon build, or "
                         f"tools/bootstrap.sh in the repository): {missing}")


def check_console_scripts_are_where_ros2_run_looks(pkg_dir):
    """``ros2 run <pkg> <exe>`` runs ``<prefix>/lib/<pkg>/<exe>`` (setup.cfg script_dir)."""
    name, _ = package_xml(pkg_dir)
    tree = ast.parse((pkg_dir / "setup.py").read_text(encoding="utf-8"))
    scripts = [n.value.split("=")[0].strip() for n in ast.walk(tree)
               if isinstance(n, ast.Constant) and isinstance(n.value, str)
               and "=" in n.value and ":" in n.value.split("=", 1)[1]]
    if not scripts:
        return
    prefix = _installed_prefix(name)
    missing = [s for s in scripts if not os.access(prefix / "lib" / name / s, os.X_OK)]
    assert not missing, f"not executable in {prefix}/lib/{name}: {missing}"


CHECKS = (
    check_runtime_imports_are_exec_depends,
    check_test_imports_are_declared,
    check_declared_python_libraries_are_imported,
    check_every_module_imports,
    check_setup_py_stays_inside_the_package,
    check_install_holds_the_source_packages_and_data,
    check_console_scripts_are_where_ros2_run_looks,
)


def check_package(pkg_dir: Path) -> None:
    """Run every check on the package in ``pkg_dir``; one AssertionError lists all that
    failed."""
    failed = []
    for check in CHECKS:
        try:
            check(Path(pkg_dir))
        except AssertionError as exc:
            failed.append(f"{check.__name__}: {exc}")
    assert not failed, "\n".join(failed)
