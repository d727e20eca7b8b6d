"""The package's import graph, counting imports inside functions: no module depends on itself through others, but
for the lazy import from a result to its report (the doctor's HTML report); the model's vocabulary (a robot's chain
included) imports nothing of the methods, and the record is a data type that imports no file format."""

import ast
import os

import didim

PACKAGE = os.path.dirname(didim.__file__)
#: (importer, imported) pairs allowed to close a cycle, each through imports inside functions only.
LAZY_ALLOWED = {("didim.doctor", "didim.report")}


def _modules():
    out = {}
    for folder, _, files in os.walk(PACKAGE):
        for f in files:
            if f.endswith(".py"):
                rel = os.path.relpath(os.path.join(folder, f), os.path.dirname(PACKAGE))[:-3].replace(os.sep, ".")
                out[rel[:-9] if rel.endswith(".__init__") else rel] = os.path.join(folder, f)
    return out


def _graph(mods):
    """module -> {imported module: True when imported at module level, else False (inside functions only)}."""
    g = {m: {} for m in mods}
    for m, path in mods.items():
        tree = ast.parse(open(path, encoding="utf-8").read())
        top = {id(n) for n in tree.body}
        pkg = m if path.endswith("__init__.py") else m.rsplit(".", 1)[0]
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom) or not node.level:
                continue
            base = pkg
            for _ in range(node.level - 1):
                base = base.rsplit(".", 1)[0]
            target = f"{base}.{node.module}" if node.module else base
            for a in node.names:
                t = f"{target}.{a.name}" if f"{target}.{a.name}" in mods else target
                while t not in mods and "." in t:  # a name from a module (or the compiled _core): its module
                    t = t.rsplit(".", 1)[0]
                if t == "didim" and not node.module and a.name == "_core":
                    continue
                if t in mods and t != m:
                    g[m][t] = g[m].get(t, False) or id(node) in top
    return g


def _reaches(g, a, b, skip):
    seen, todo = set(), [a]
    while todo:
        x = todo.pop()
        for y in g[x]:
            if (x, y) in skip:
                continue
            if y == b:
                return True
            if y not in seen:
                seen.add(y)
                todo.append(y)
    return False


def test_no_import_cycle_but_the_allowed_lazy_ones():
    g = _graph(_modules())
    for a, b in LAZY_ALLOWED:
        assert g[a].get(b) is False, f"{a} imports {b} at module level (allowed only inside a function)"
    cycles = [(a, b) for a in g for b in g[a] if (a, b) not in LAZY_ALLOWED and _reaches(g, b, a, LAZY_ALLOWED)]
    assert not cycles, f"import cycles through {cycles}"


def test_the_model_module_imports_only_the_core_the_checks_and_the_errors():
    """The model's vocabulary: the core's terms, and a robot's link side (its chain, which itself imports only the
    core, the checks and the errors); nothing of the methods."""
    g = _graph(_modules())
    assert set(g["didim.model"]) <= {"didim._checks", "didim._errors", "didim.robots.chain"}, g["didim.model"]
    assert set(g["didim.robots.chain"]) <= {"didim._checks", "didim._errors", "didim.formats._io"}, \
        g["didim.robots.chain"]


def test_the_record_imports_no_file_format():
    g = _graph(_modules())
    assert not set(g["didim.recording"]) & {"didim.formats.loaders", "didim.formats._io"}, g["didim.recording"]


def test_the_layers_plant_methods_doctor_command_line():
    """The way the README's layout section shows: the plant's vocabulary (model, record, chain, controllers, units)
    imports no method; the methods (``didim.methods``) import neither the doctor nor the entry points; the doctor
    does not import the command line."""
    g = _graph(_modules())
    upper = lambda m: m.startswith(("didim.methods", "didim.doctor")) or m in ("didim.api", "didim.cli")  # noqa: E731
    for m in ("didim.model", "didim.recording", "didim.robots.chain", "didim.controllers", "didim.units"):
        assert not [x for x in g[m] if upper(x)], (m, g[m])
    methods = [m for m in g if m.startswith("didim.methods")]
    assert {"didim.methods.identification", "didim.methods.oe", "didim.methods.didim_loop",
            "didim.methods.friction_law", "didim.methods.robot"} <= set(methods)
    for m in methods:
        assert not [x for x in g[m] if x.startswith("didim.doctor") or x in ("didim.api", "didim.cli")], (m, g[m])
    for m in [m for m in g if m.startswith("didim.doctor")]:
        assert "didim.cli" not in g[m], m
