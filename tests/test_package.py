"""Packaging: the public API, the Qt-free core, and the npe2 manifest."""

import subprocess
import sys
from pathlib import Path

import numpy as np

import napari_lfdeblur

ROOT = Path(__file__).resolve().parents[1]


def test_every_public_name_resolves():
    for name in napari_lfdeblur.__all__:
        assert getattr(napari_lfdeblur, name) is not None, name


def test_readme_python_api_names_are_top_level():
    """Every function or class the README's Python API list names is ``napari_lfdeblur.<name>``."""
    import importlib
    import re

    import pkgutil

    section = (ROOT / "README.md").read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    bullets = "\n".join(line for line in section.splitlines() if line.startswith(("- ", "  ")))
    public = [m.name for m in pkgutil.iter_modules(napari_lfdeblur.__path__) if not m.name.startswith("_")]
    modules = [importlib.import_module(f"napari_lfdeblur.{m}") for m in public]
    methods = {"estimate", "from_json", "from_metadata", "preset", "replace", "to_json"}  # of BlindParams and Progress
    quoted = set(re.findall(r"`([A-Za-z_]\w*)(?:`|\()", bullets)) - methods  # `name` or `name(...)`
    named = {n for n in quoted if any(callable(getattr(m, n, None)) for m in modules)}
    assert len(named) > 20  # the list was found
    assert sorted(named - set(napari_lfdeblur.__all__)) == []
    # a call the list shows is a top-level name, or a method of one (a renamed function is not left out)
    calls = set(re.findall(r"`(?:[\w.]+\.)?([A-Za-z_]\w*)\(", bullets))
    assert sorted(calls - set(napari_lfdeblur.__all__) - methods) == []
    import dataclasses

    assert all(callable(getattr(napari_lfdeblur.BlindParams, m, None)) for m in methods - {"estimate"})
    assert "estimate" in {f.name for f in dataclasses.fields(napari_lfdeblur.Progress)}  # a callable field


def test_core_imports_neither_qt_nor_napari():
    code = (
        "import sys, napari_lfdeblur as m\n"
        "[getattr(m, n) for n in m.__all__]\n"
        "import napari_lfdeblur.cli, napari_lfdeblur.demo\n"
        "bad = sorted(k for k in sys.modules if k.split('.')[0] in "
        "('napari', 'qtpy', 'PyQt5', 'PyQt6', 'PySide2', 'PySide6', 'magicgui', 'vispy'))\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_widgets_module_is_the_manifests_widgets():
    """napari_lfdeblur.widgets, the scripting entry, holds the very classes the plugin menu opens."""
    import importlib

    from npe2 import PluginManifest

    import napari_lfdeblur.widgets as widgets

    manifest = PluginManifest.from_file(ROOT / "napari.yaml")
    commands = {c.id: c.python_name for c in manifest.contributions.commands}
    opened = set()
    for contribution in manifest.contributions.widgets:
        module, _, attr = commands[contribution.command].partition(":")
        opened.add(getattr(importlib.import_module(module), attr))
    listed = {getattr(widgets, name) for name in widgets.__all__}
    assert opened and opened <= listed
    assert all(hasattr(widgets, name) for name in widgets.__all__)


def test_widgets_module_says_what_it_needs_without_napari():
    code = (
        "import sys; sys.modules['napari'] = None\n"
        "try:\n    import napari_lfdeblur.widgets\n"
        "except ImportError as e:\n    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    assert 'napari_lfdeblur.widgets needs napari and Qt' in out and 'napari-lfdeblur[napari]' in out


def test_manifest_symlink_and_name():
    link = ROOT / "src" / "napari_lfdeblur" / "napari.yaml"
    assert link.is_symlink() and link.resolve() == (ROOT / "napari.yaml").resolve()
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    from npe2 import PluginManifest

    manifest = PluginManifest.from_file(ROOT / "napari.yaml")
    assert manifest.name == project["name"] == "napari-lfdeblur"


def test_manifest_validates_and_its_commands_import():
    from npe2 import PluginManifest

    manifest = PluginManifest.from_distribution("napari-lfdeblur")
    manifest.validate_imports()
    assert manifest.contributions.sample_data and manifest.contributions.readers


def test_sample_data_contributions():
    from napari_lfdeblur._napari.sample_data import lytro_sample_layer, synthetic_blurred_sample
    from napari_lfdeblur import simulate_blur, synthetic_scene

    (data, kwargs, kind), = synthetic_blurred_sample()
    sharp, _ = synthetic_scene((9, 9, 128, 128), n_layers=3, color=True, seed=0)
    cp = kwargs["metadata"]["control_points"]
    np.testing.assert_allclose(data, simulate_blur(sharp, cp, n_times=kwargs["metadata"]["n_times"]), atol=1e-6)
    assert kind == "image" and kwargs["rgb"] and kwargs["axis_labels"] == ("v", "u", "y", "x")
    (lytro, kw, _), = lytro_sample_layer()
    assert lytro.shape == (9, 9, 128, 128, 3) and "CC BY 4.0" in kw["metadata"]["source"]


# ------------------------------------------------------------ code layout rules

SRC = ROOT / "src" / "napari_lfdeblur"


def _modules():
    return sorted(p for p in SRC.rglob("*.py"))


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _is_module(path, node, name) -> bool:
    """Whether ``from <node.module> import name`` in ``path`` imports a module (a private module is fine)."""
    base = path.parent
    for _ in range(max(node.level - 1, 0)):
        base = base.parent
    if node.level == 0:
        base = SRC.parent
    base = base.joinpath(*(node.module or "").split(".")) if node.module else base
    return (base / f"{name}.py").exists() or (base / name / "__init__.py").exists()


def test_no_module_imports_a_private_name_from_another_module():
    import ast

    bad = []
    private_modules = {p.stem for p in SRC.rglob("_*.py")} | {p.name for p in SRC.rglob("_*") if p.is_dir()}
    for path in _modules():
        tree = ast.parse(path.read_text(), filename=str(path))
        module_aliases = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("napari_lfdeblur")):
                for alias in node.names:
                    if _is_private(alias.name) and not _is_module(path, node, alias.name):
                        bad.append(f"{path.relative_to(SRC)}:{node.lineno} imports {alias.name}")
                    else:
                        module_aliases.add(alias.asname or alias.name)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("napari_lfdeblur"):
                        module_aliases.add((alias.asname or alias.name).split(".")[0])
        for node in ast.walk(tree):  # name._private, or through a chain: package.module._private
            if isinstance(node, ast.Attribute) and _is_private(node.attr) and node.attr not in private_modules:
                root = node.value
                while isinstance(root, ast.Attribute):
                    root = root.value
                if isinstance(root, ast.Name) and root.id in module_aliases:
                    bad.append(f"{path.relative_to(SRC)}:{node.lineno} uses {ast.unparse(node)}")
    assert not bad, "\n".join(bad)


def test_modules_and_functions_stay_short():
    """No module over 500 lines unless a ``# long module:`` comment says why, no function over 80 (its docstring
    aside) unless a ``# long:`` comment in it says why."""
    import ast

    long = []
    for path in _modules():
        text = path.read_text()
        lines = text.splitlines()
        if len(lines) > 500 and "# long module:" not in text:
            long.append(f"{path.relative_to(SRC)}: {len(lines)} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                doc = node.body[0]
                if isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant) and isinstance(doc.value.value, str):
                    n -= doc.end_lineno - doc.lineno + 1
                body = "\n".join(lines[node.lineno - 1 : node.end_lineno])
                if n > 80 and "# long:" not in body:
                    long.append(f"{path.relative_to(SRC)}:{node.lineno} {node.name}: {n} lines")
    assert not long, "\n".join(long)


def test_no_backslash_continuations():
    bad = [f"{p.relative_to(SRC)}:{i}" for p in _modules()
           for i, line in enumerate(p.read_text().splitlines(), 1) if line.rstrip().endswith("\\")]
    assert not bad, bad


def test_docs_and_code_stand_alone():
    """Neither code nor docs send a reader to files outside the repository, or tell its history."""
    import re

    # the shared notes beside the repository (in any spelling but the project's own docs/model.md), and history
    pattern = re.compile(r"\.\./shared|findings\.md|(?-i:M)odel\.md|(?<!napari )\bsession", re.IGNORECASE)
    files = [*_modules(), SRC / "napari.yaml", ROOT / "pyproject.toml", ROOT / "README.md",
             *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "docs").rglob("*.py"))]
    bad = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}" for p in files
           for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert not bad, "\n".join(bad)


def test_public_modules_list_only_names_they_define():
    import importlib

    for module in sorted({v for v in napari_lfdeblur._PUBLIC.values()}):
        mod = importlib.import_module(f"napari_lfdeblur.{module}")
        for name in getattr(mod, "__all__", []):
            assert hasattr(mod, name), f"napari_lfdeblur.{module}.__all__ lists {name}, which it lacks"


def test_reader_patterns_cover_every_file_the_reader_detects(tmp_path):
    """napari offers the plugin's reader only for names its manifest's patterns match, as npe2 matches them
    (suffixes without case, the rest of the name as it is, the patterns lower-cased)."""
    from npe2 import PluginManager, PluginManifest

    from napari_lfdeblur import io
    from napari_lfdeblur.io import detect_layout

    plugins = PluginManager()
    plugins.register(PluginManifest.from_file(ROOT / "napari.yaml"))

    def offered(name):
        return [r.command for r in plugins.iter_compatible_readers([str(tmp_path / name)])] == [
            "napari-lfdeblur.get_reader"]

    suffixes = [*io._SUFFIX_LAYOUT, *io._IMAGE_SUFFIXES]  # every suffix the reader knows by name
    names = [f"a{s}" for s in io._SUFFIX_LAYOUT] + [f"A{s.upper()}" for s in io._SUFFIX_LAYOUT]
    names += [f"{stem}{s}" for s in suffixes for stem in ("x.eslf", "X.ESLF", "x_eslf", "x.Eslf")]
    for name in names:
        (tmp_path / name).write_bytes(b"")
        assert detect_layout(tmp_path / name)  # the reader knows the kind by the name
        assert offered(name), name
    # what the README says napari does not pass: ESLF in upper case inside the name, and other images
    assert not offered("IMG_ESLF.png") and not offered("photo.png")
