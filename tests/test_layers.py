"""The package's import graph, read from the source with ``ast``: no import circle, the core never imports the
application layer, and every import inside a function has a reason listed here (:data:`DEFERRED`)."""

import ast
import pathlib
import subprocess
import sys

from conftest import HANG_S

ROOT = pathlib.Path(__file__).resolve().parents[1]
# The installed package's folders (pyproject's package-dir): the benchmarks are scripts of the source tree, read too.
FOLDERS = {"sb3_genrl": ROOT / "sb3_genrl", "sb3_genrl.envs": ROOT / "envs", "sb3_genrl.baselines": ROOT / "baselines"}
SCRIPTS = ROOT / "benchmarks"

# The core: the algorithm, the generative models, the metrics, the data, the wrapper and the batched VecEnv, with the
# small modules they share. It never imports the application layer below.
CORE = (
    "sb3_genrl",  # the package's __init__
    "sb3_genrl.genrl",
    "sb3_genrl.generative",
    "sb3_genrl.metrics",
    "sb3_genrl.data",
    "sb3_genrl.wrappers",
    "sb3_genrl.vec_env",
    "sb3_genrl.checks",
    "sb3_genrl.utils",
    "sb3_genrl.provenance",
    "sb3_genrl.version",
    "sb3_genrl.task_ids",
    "sb3_genrl.markdown",
    "sb3_genrl.curves",
    "sb3_genrl.hyperparams",
)
APPLICATION = (
    "sb3_genrl.envs",
    "sb3_genrl.baselines",
    "sb3_genrl.run",
    "sb3_genrl.study",
    "sb3_genrl.zoo",
    "sb3_genrl.cli",
    "sb3_genrl.showcase",
    "sb3_genrl.video",
    "benchmarks",
)

# Imports kept inside a function, each with its reason: an optional extra, a platform, or a cost that the import of the
# module (and `import sb3_genrl`, which imports the tasks) should not pay.
MPL = "matplotlib costs about 0.8 s, only when a plot is drawn"
ZOO = "rl-zoo3, the optional extra zoo"
STATS = "scipy.stats costs about 0.5 s, only when a correlation or DwPR's interventions are computed"
DEFERRED = {
    # the core
    ("sb3_genrl.generative.torch_generator", "torch.utils.tensorboard"): "TensorBoard only when a log folder is given",
    ("sb3_genrl.utils", "fcntl"): "the POSIX lock, on POSIX only",
    ("sb3_genrl.utils", "msvcrt"): "the Windows lock, on Windows only",
    ("sb3_genrl.curves", "matplotlib.backends.backend_agg"): MPL,
    ("sb3_genrl.curves", "matplotlib.figure"): MPL,
    # the tasks, imported by `import sb3_genrl`
    ("sb3_genrl.envs.basketball", "matplotlib.patches"): MPL,
    ("sb3_genrl.envs.coverage", "matplotlib.backends.backend_agg"): MPL,
    ("sb3_genrl.envs.coverage", "matplotlib.figure"): MPL,
    ("sb3_genrl.envs.coverage", "matplotlib.patches"): MPL,
    ("sb3_genrl.envs.coverage", "scipy.spatial"): "scipy.spatial costs about 0.5 s, only when coverage is measured",
    ("sb3_genrl.envs.fetch_mujoco", "gymnasium_robotics.utils"): "Gymnasium-Robotics, the optional extra robotics",
    ("sb3_genrl.envs.metaworld", "metaworld"): "Meta-World, the optional extra metaworld",
    ("sb3_genrl.envs.metaworld", "metaworld.policies"): "Meta-World, the optional extra metaworld",
    # the generator measures, which every `genrl` command imports
    ("sb3_genrl.metrics.bootstrap", "scipy.stats"): STATS,
    ("sb3_genrl.metrics.correlation", "scipy.stats"): STATS,
    ("sb3_genrl.metrics.dwpr", "scipy.stats"): STATS,
    ("sb3_genrl.metrics.plots", "matplotlib.backends.backend_agg"): MPL,
    ("sb3_genrl.metrics.plots", "matplotlib.figure"): MPL,
    # the application layer
    ("sb3_genrl.baselines.compare", "matplotlib.backends.backend_agg"): MPL,
    ("sb3_genrl.baselines.compare", "matplotlib.figure"): MPL,
    ("sb3_genrl.showcase", "imageio_ffmpeg"): "MP4 only: without imageio-ffmpeg a GIF is still written",
    ("sb3_genrl.video", "imageio_ffmpeg"): "MP4 only: without imageio-ffmpeg an MP4 is refused as one error, a GIF written",
    ("sb3_genrl.study.cluster", "ray"): "Ray, the optional extra ray",
    ("sb3_genrl.study.runner", "ray"): "Ray, the optional extra ray",
    ("sb3_genrl.zoo", "rl_zoo3.hyperparams_opt"): ZOO,
    ("sb3_genrl.zoo", "rl_zoo3.utils"): ZOO,
    ("sb3_genrl.zoo.__main__", "rl_zoo3.enjoy"): ZOO,
    ("sb3_genrl.zoo.__main__", "rl_zoo3.train"): ZOO,
    ("sb3_genrl.zoo.__main__", "sb3_genrl.zoo.experiment"): "built on rl-zoo3 and optuna, the optional extra zoo",
    ("benchmarks.fetch_results", "matplotlib"): MPL,
    ("benchmarks.fetch_results", "matplotlib.pyplot"): MPL,
    ("benchmarks.genrl", "matplotlib"): MPL,
    ("benchmarks.genrl", "matplotlib.pyplot"): MPL,
    ("benchmarks.precision_recall", "prdc"): "prdc, the optional extra bench",
}


def _modules() -> dict[str, pathlib.Path]:
    found = {}
    for package, folder in FOLDERS.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if package == "sb3_genrl" and parts[0] in ("envs", "baselines"):
                continue
            found[".".join([package, *[part for part in parts if part != "__init__"]])] = path
    for path in SCRIPTS.glob("*.py"):
        found[f"benchmarks.{path.stem}"] = path
    return found


def _in(module: str, layer: tuple[str, ...]) -> bool:
    """Whether ``module`` is one of ``layer``'s modules or inside one of its packages (the root package: itself only)."""
    return any(module == name or (name != "sb3_genrl" and module.startswith(name + ".")) for name in layer)


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """The imports under ``if TYPE_CHECKING:``, which never run."""
    skipped = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped |= {id(sub) for statement in node.body for sub in ast.walk(statement)}
    return skipped


def _imports(modules: dict[str, pathlib.Path]) -> list[tuple[str, str, bool]]:
    """``(importer, imported, deferred)`` for every import of a module in ``modules`` or of anything else."""

    def resolve(name: str) -> str:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    edges = []
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skipped = _type_checking_nodes(tree)
        deferred = {
            id(sub)
            for node in ast.walk(tree)
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            for sub in ast.walk(node)
        }
        for node in ast.walk(tree):
            if id(node) in skipped:
                continue
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                    base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
                names = [f"{base}.{alias.name}" for alias in node.names]
            else:
                continue
            external = node.module if isinstance(node, ast.ImportFrom) and not node.level else None
            for name in names:
                target = resolve(name) or external or name
                if target != module:
                    edges.append((module, target, id(node) in deferred))
    return edges


MODULES = _modules()
EDGES = _imports(MODULES)


def test_no_import_circle():
    graph: dict[str, set[str]] = {module: set() for module in MODULES}
    for importer, imported, _ in EDGES:
        if imported in MODULES:
            graph[importer].add(imported)
    circles, state = [], dict.fromkeys(graph, 0)  # 0 unseen, 1 on the path, 2 done

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for imported in sorted(graph[module]):
            if state[imported] == 1:
                circles.append(path[path.index(imported) :] + [imported])
            elif state[imported] == 0:
                visit(imported, [*path, imported])
        state[module] = 2

    for module in sorted(graph):
        if state[module] == 0:
            visit(module, [module])
    assert circles == []


def test_the_core_never_imports_the_application_layer():
    wrong = sorted({(a, b) for a, b, _ in EDGES if _in(a, CORE) and _in(b, APPLICATION)})
    assert wrong == []


def test_every_module_is_in_one_layer():
    assert sorted(m for m in MODULES if not (_in(m, APPLICATION) or _in(m, CORE))) == []


def test_the_deferred_imports_are_the_listed_ones():
    deferred = {(a, b) for a, b, is_deferred in EDGES if is_deferred}
    assert deferred == set(DEFERRED)


def test_the_command_line_starts_without_scipy_stats_or_matplotlib():
    """``genrl`` imports every command's module; the plots and the statistics load only when a command draws or
    computes them (:data:`DEFERRED`), so that a command's start-up is torch's and SB3's."""
    code = "import sys, sb3_genrl.cli; print(sorted(m for m in ('scipy.stats', 'matplotlib') if m in sys.modules))"
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=HANG_S)
    assert loaded.stdout.strip() == "[]"
