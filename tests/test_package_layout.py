"""The package's layout: no import circle in src/mope, a short top level, no oversized class or function, and the
old module paths of the moved modules still importing the same modules."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

import mope

SRC = Path(__file__).parents[1] / "src"
PACKAGE = SRC / "mope"


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_names(tree: ast.Module) -> list[str]:
    """Every module path this file imports, at the top or inside functions (``if TYPE_CHECKING:`` blocks aside),
    ``importlib.import_module`` of a constant and the former module a package serves
    (:func:`mope.moved.former_module_names`) included."""
    type_only = {id(n) for node in ast.walk(tree)
                 if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
                 for stmt in node.body for n in ast.walk(stmt)}
    constants = {t.id: node.value.value for node in tree.body if isinstance(node, ast.Assign)
                 and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)
                 for t in node.targets if isinstance(t, ast.Name)}
    names = []
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names += [f"{node.module}.{a.name}" for a in node.names] + [node.module]
        elif isinstance(node, ast.Call) and ast.unparse(node.func).endswith("import_module") and node.args:
            arg = node.args[0]
            value = arg.value if isinstance(arg, ast.Constant) else constants.get(getattr(arg, "id", ""))
            if isinstance(value, str):
                names.append(value)
        elif isinstance(node, ast.Call) and ast.unparse(node.func) == "former_module_names":
            names += [a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)]
    return names


def import_graph() -> dict[str, set[str]]:
    """Module -> the modules of src/mope it imports (``from a.b import c`` points at ``a.b.c`` when that is a
    module, else at ``a.b``)."""
    files = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        targets = set()
        for imported in imported_names(ast.parse(path.read_text())):
            if imported.startswith("mope") and imported in files:
                targets.add(imported)
        # ``from a.b import c`` listed both a.b.c and a.b: keep only the most specific
        graph[name] = {t for t in targets if t != name and not any(u.startswith(t + ".") for u in targets)}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_circle_in_src() -> None:
    graph = import_graph()
    assert "mope.agent.agent" in graph["mope.agent"]  # the package serves the former module's names
    assert "mope.agent.losses" in graph["mope.agent.agent"] and "mope.agent.runner" in graph["mope.agent.base"]
    assert circles(graph) == []


def test_the_circle_finder_finds_a_circle() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    source = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import mope.x\ndef f():\n    import mope.y\n"
    assert imported_names(ast.parse(source)) == ["typing.TYPE_CHECKING", "typing", "mope.y"]


def test_at_most_12_python_files_at_the_top_level() -> None:
    assert len(list(PACKAGE.glob("*.py"))) <= 12


def test_no_class_over_250_lines_and_no_function_over_60_in_src() -> None:
    spec = importlib.util.spec_from_file_location("check_sizes", SRC.parent / "scripts" / "check_sizes.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.oversized(SRC, 250, 60) == []


@pytest.mark.parametrize(("old", "new"), sorted(mope.MOVED_MODULES.items()))
def test_an_old_module_path_imports_the_moved_module(old: str, new: str) -> None:
    assert importlib.import_module(old) is importlib.import_module(new)
    assert getattr(mope, old.rsplit(".", 1)[1]) is sys.modules[new]
    assert sys.modules[new].__spec__.name == new  # the alias left the module's own spec in place


def test_the_former_modules_names_come_from_their_packages() -> None:
    from mope.replay import ReplayBuffer

    import mope.agent.agent
    import mope.agent.replay
    import mope.evaluation.evaluator
    import mope.experiments.runs
    from mope.agent import MoPE, agent_class
    from mope.evaluation import Evaluator, solutions
    from mope.experiments import read_metrics, train_run

    assert (MoPE, agent_class) == (mope.agent.agent.MoPE, mope.agent.agent.agent_class)
    assert (Evaluator, solutions) == (mope.evaluation.evaluator.Evaluator, mope.evaluation.evaluator.solutions)
    assert (train_run, read_metrics) == (mope.experiments.runs.train_run, mope.experiments.runs.read_metrics)
    assert ReplayBuffer is mope.agent.replay.ReplayBuffer
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        mope.agent.nothing  # noqa: B018


def test_a_moved_name_says_where_it_went() -> None:
    import mope.envs.batched

    with pytest.raises(AttributeError, match="from mope.envs import make_batched"):
        mope.envs.batched.make_batched  # noqa: B018


def test_old_paths_work_in_a_fresh_interpreter() -> None:
    code = ("from mope.reproduce import reproduce_dst; from mope.experiments import train_run; "
            "from mope.agent import MoPE; import mope.jobs, mope.experiments.jobs; "
            "assert mope.jobs is mope.experiments.jobs; print('ok')")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr


def test_import_mope_and_bad_input_do_not_import_torch(tmp_path) -> None:
    """``import mope`` leaves torch unimported until a torch-backed name is used (``mope.MoPE`` and the other names of
    ``mope._LAZY``), ``mope train`` refuses a bad environment or a bad ``--resume`` folder before importing it, and
    ``mope act`` a preference of the wrong length for a run folder: such a command answers in about 1 s, where
    torch's import alone takes 2-4 s."""
    from mope import Config

    Config(env_id="deep-sea-treasure-v0").save(tmp_path / "config.json")  # a run folder's config (2 objectives)
    code = ("import sys, mope; assert 'torch' not in sys.modules, 'import mope imported torch'; "
            "from mope import Config, make_env; assert 'torch' not in sys.modules; "
            "from mope import MoPE, Evaluator, solutions; assert 'torch' in sys.modules; "
            "assert MoPE is mope.agent.agent.MoPE and mope.Evaluator is mope.evaluation.evaluator.Evaluator; "
            "print('ok')")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr
    for args in (["train", "--env", "deep-sea-treasur-v0"], ["train", "--resume", "no/such/run"],
                 ["act", str(tmp_path), "--pref", "0.3,0.3,0.4"]):
        code = ("import sys, mope.cli\n"
                f"try:\n    mope.cli.app({args!r})\nexcept SystemExit as exc:\n"
                "    print(exc.code, 'torch' in sys.modules)")
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
        assert res.stdout.split() == ["2", "False"], (args, res.stdout, res.stderr)
