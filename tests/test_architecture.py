"""The shape of the code: no import circles, the hooks documented, plugins checked by pluggy."""

import ast
import inspect
import re
import types
from pathlib import Path

import pytest

from harness import FilterSpec, hookimpl, hookspecs, load_plugins

ROOT = Path(__file__).resolve().parents[1]


def _imports(package: str) -> dict[str, set[str]]:
    """Module -> the modules of the same top-level packages it imports (absolute and relative)."""
    graph = {}
    tops = ("harness", "plugins")
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        base = name if rel.name == "__init__" else name.rpartition(".")[0]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name.split(".")[0] in tops}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    parent = base.split(".")
                    parent = parent[: len(parent) - node.level + 1]
                    mod = ".".join(parent + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                if mod.split(".")[0] in tops:
                    deps.add(mod)
                    deps |= {f"{mod}.{a.name}" for a in node.names}
        graph[name] = deps
    known = set(graph)
    return {m: {d for d in deps if d in known and d != m} for m, deps in graph.items()}


def _cycle(graph):
    state, stack = {}, []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for d in sorted(graph[m]):
            if state.get(d) == 1:
                return stack[stack.index(d):] + [d]
            if d not in state:
                found = visit(d)
                if found:
                    return found
        state[m] = 2
        stack.pop()
        return None

    for m in sorted(graph):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


@pytest.mark.parametrize("package", ["harness", "plugins"])
def test_no_import_circles(package):
    graph = _imports(package)
    # a package's __init__ re-exporting its modules is not a circle with them: drop those edges
    for module, deps in graph.items():
        graph[module] = {d for d in deps if not module.startswith(d + ".")}
    assert _cycle(graph) is None, f"import circle: {' -> '.join(_cycle(graph))}"


def test_the_library_never_imports_the_cli():
    graph = _imports("harness")
    users = sorted(m for m, deps in graph.items() if not m.startswith("harness.cli")
                   and any(d.startswith("harness.cli") for d in deps))
    assert not users, f"library modules importing the CLI: {users}"


def test_plugins_import_only_the_public_api():
    offenders = []
    for path in (ROOT / "plugins").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("harness."):
                offenders.append(f"{path.relative_to(ROOT)}: from {node.module}")
            if isinstance(node, ast.Import):
                offenders += [f"{path.relative_to(ROOT)}: import {a.name}" for a in node.names
                              if a.name.startswith("harness.")]
    assert not offenders, offenders


def test_every_hook_is_documented_with_its_signature():
    """In datasette's manner: docs/architecture.md shows each hook spec as ``name(args)``."""
    doc = (ROOT / "docs" / "architecture.md").read_text()
    specs = [f for n, f in vars(hookspecs).items() if inspect.isfunction(f) and hasattr(f, "denoise_harness_spec")]
    assert len(specs) >= 5
    for fn in specs:
        signature = f"{fn.__name__}({', '.join(inspect.signature(fn).parameters)})"
        assert f"`{signature}`" in doc, f"docs/architecture.md does not document the hook `{signature}`"


def test_a_misspelled_hook_is_an_error_naming_the_plugin():
    mod = types.ModuleType("typo_plugin")

    @hookimpl
    def register_filter():
        return [FilterSpec(name="never", version="0", factory=None)]

    mod.register_filter = register_filter
    reg = load_plugins(extra=[mod])
    record = reg.record("module", "typo_plugin")
    assert record.status == "broken" and "unknown hook(s) ['register_filter']" in record.error
    assert "register_filters" in record.error and "never" not in reg.filters
    assert "passthrough" in reg.filters


def test_open_scene_takes_the_first_result(tmp_path):
    calls = []

    def plugin(name, answer, **marks):
        mod = types.ModuleType(name)

        @hookimpl(**marks)
        def open_scene(path):
            calls.append(name)
            return answer

        mod.open_scene = open_scene
        return mod

    reg = load_plugins(extra=[plugin("first", "scene-a", tryfirst=True), plugin("second", "scene-b")],
                       entry_points=False)
    assert reg.open_scene(tmp_path) == "scene-a" and calls == ["first"]
    assert re.search("no scene plugin recognises it",
                     str(pytest.raises(ValueError, load_plugins(entry_points=False).open_scene, tmp_path).value))
