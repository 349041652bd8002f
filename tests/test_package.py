"""The package's surface: ``import bve_mj`` is cheap and every exported name resolves."""

import subprocess
import sys

import bve_mj


def test_importing_the_package_loads_nothing_heavy():
    code = (
        "import sys, bve_mj; from bve_mj.config import Settings; Settings(); "
        "heavy = [m for m in ('scipy.optimize', 'pinocchio', 'mujoco', 'cv2') if m in sys.modules]; "
        "print(','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_every_exported_name_resolves():
    for name in bve_mj.__all__:
        assert getattr(bve_mj, name) is not None, name
    assert set(bve_mj.__all__) <= set(dir(bve_mj))
    try:
        bve_mj.not_a_name  # noqa: B018
    except AttributeError as exc:
        assert "not_a_name" in str(exc)
    else:
        raise AssertionError("an unknown name resolved")


def test_one_blas_thread_reaches_blas_loaded_after_a_light_import():
    """``import bve_mj`` loads no BLAS; the CLI's and the workers' one-thread limit must still
    reach SciPy's (a multi-threaded BLAS changed an episode's path: plum, seed 2710367621,
    4.33 mm by the CLI before the lazy import, 4.25 after)."""
    code = (
        "import bve_mj; from bve_mj.threads import one_blas_thread\n"
        "from threadpoolctl import threadpool_info\n"
        "with one_blas_thread():\n"
        "    import scipy.optimize\n"
        "    libs = [i for i in threadpool_info() if i['user_api'] == 'blas']\n"
        "    print(len(libs), max(i['num_threads'] for i in libs))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    n_libs, threads = map(int, out.stdout.split())
    assert n_libs >= 1 and threads == 1


LAYERS = [
    {"errors", "threads", "linalg", "atomic"},
    {"config"},
    {"geometry"},
    {"estimation"},
    {"planning", "perception"},
    {"robot"},
    {"sim"},
    {"loop"},
    {"campaigns", "gym"},
    {"reporting"},
    {"cli"},
]
"""The package's layers from the bottom: a module imports only from its own layer or below
(the package root, which re-exports, and its ``__version__`` are above them all)."""


def _imports_by_part() -> dict[str, set[str]]:
    import ast
    from pathlib import Path

    root = Path(bve_mj.__file__).parent
    out: dict[str, set[str]] = {}
    for path in root.rglob("*.py"):
        rel = path.relative_to(root)
        if rel == Path("__init__.py"):
            continue
        part = rel.parts[0].removesuffix(".py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = (
                [node.module]
                if isinstance(node, ast.ImportFrom) and node.module
                else [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else []
            )
            for name in names:
                if name.startswith("bve_mj."):
                    out.setdefault(part, set()).add(name.split(".")[1])
    return out


def test_no_module_imports_from_a_layer_above_its_own():
    rank = {part: i for i, layer in enumerate(LAYERS) for part in layer}
    imports = _imports_by_part()
    assert set(imports) <= set(rank), f"a part outside the layers: {set(imports) - set(rank)}"
    upward = sorted(
        f"{part} -> {used}"
        for part, used_parts in imports.items()
        for used in used_parts
        if rank[used] > rank[part]
    )
    assert not upward, upward


MAX_MODULE_LINES = 400


def test_no_module_is_longer_than_a_reader_can_hold():
    """One concept per module: none over MAX_MODULE_LINES lines (split by concept when one
    grows past it, as scene.py became scene, crop, foliage, ...)."""
    from pathlib import Path

    root = Path(bve_mj.__file__).parent
    lines = {
        str(p.relative_to(root)): len(p.read_text(encoding="utf-8").splitlines()) for p in root.rglob("*.py")
    }
    long = {name: n for name, n in lines.items() if n > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def test_every_suite_scenario_ships_in_the_wheel():
    """pyproject's data-files list every scenario of the suite (a non-editable install finds
    the suite through them: a scene left out is missing there)."""
    from pathlib import Path

    import tomllib

    root = Path(__file__).resolve().parents[1]
    files = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["data-files"]
    shipped = set(files["share/bve_mj/scenarios"])
    suite = {p.relative_to(root).as_posix() for p in (root / "examples/scenarios/suite").glob("*.toml")}
    assert suite == shipped, (suite - shipped, shipped - suite)


def test_the_ci_constraints_pin_every_requirement_within_its_range():
    """``.ci/constraints.txt`` (what ``.ci/run`` installs under) pins each of pyproject's
    requirements, the extras' too, to a version its range allows: a dependency added without
    a pin, or a range moved past the pin, fails here before CI installs something else."""
    from pathlib import Path

    import tomllib
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    root = Path(__file__).resolve().parents[1]
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    pins = {}
    for line in (root / ".ci/constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, version = line.split("==")
            pins[canonicalize_name(name)] = version.strip()
    wanted = [
        *project["dependencies"],
        *(r for group in project["optional-dependencies"].values() for r in group),
    ]
    for text in wanted:
        req = Requirement(text)
        if req.marker is not None and not req.marker.evaluate():
            continue  # e.g. tomli on Python < 3.11
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} has no pin in .ci/constraints.txt"
        assert req.specifier.contains(pins[name], prereleases=True), (text, pins[name])
