"""Build the API reference of ``import rwt`` from its docstrings, with pdoc.

``python -m tests.docs.api_reference OUT`` (repository root, ``src`` on
``PYTHONPATH``, pdoc from the ``test`` extra) writes ``OUT/rwt.html``, a page
per namespace (``OUT/rwt/tf.html``...) and ``OUT/index.html``, and exits 1 on
any pdoc warning (an annotation it cannot resolve, a member it cannot place).
docs/README.md says how to read it; tests/docs/test_api_reference.py builds it
in CI.

Two things rwt does on purpose would mislead pdoc, and are undone here, in
this process only:

- ``rwt`` sets each name's ``__module__`` to its namespace (so the reference
  reads ``rwt.Graph``, ``rwt.tf.TFBuffer``), and pdoc resolves string annotations (``from __future__
  import annotations``) in the module ``__module__`` names: here they are
  resolved first in the module that defines them, TYPE_CHECKING imports
  included, so ``Topic`` in a Zenoh method stays the Zenoh link's, not
  ``rwt.Topic``;
- pdoc reads a class's source (its attributes, "view source") from the file of
  ``__module__``: ``source_of`` gives it the defining module's.
"""

from __future__ import annotations

import ast
import builtins
import contextlib
import importlib
import inspect
import re
import sys
import warnings
from pathlib import Path
from typing import Any

from rwt._names import PUBLIC


def ours(module: str) -> bool:
    """Whether ``module`` is one of rwt's packages."""
    return module.split(".", maxsplit=1)[0].startswith("rwt")


_NAMESPACES: dict[str, dict[str, Any]] = {}


def namespace_of(module_name: str) -> dict[str, Any]:
    """The names annotations in ``module_name`` may use: its globals and TYPE_CHECKING's."""
    if module_name not in _NAMESPACES:
        module = sys.modules[module_name]
        namespace = dict(vars(module))
        if ours(module_name):
            for node in ast.parse(inspect.getsource(module)).body:
                if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                    code = ast.Module(body=node.body, type_ignores=[])
                    exec(compile(code, module_name, "exec"), namespace)
        _NAMESPACES[module_name] = namespace
    return _NAMESPACES[module_name]


def _resolve(function: Any) -> None:
    """Replace ``function``'s string annotations by what they name where it is defined."""
    function = inspect.unwrap(function)
    annotations = getattr(function, "__annotations__", None)
    globals_ = getattr(function, "__globals__", None)
    if not annotations or globals_ is None or not ours(globals_.get("__name__", "")):
        return
    namespace = namespace_of(globals_["__name__"])
    for name, annotation in list(annotations.items()):
        if isinstance(annotation, str):
            with contextlib.suppress(Exception):  # left as text: pdoc then warns
                annotations[name] = _evaluate(annotation, namespace)


def _evaluate(annotation: str, namespace: dict[str, Any]) -> Any:
    value = eval(annotation, namespace, vars(builtins))
    if isinstance(value, str):  # a string alias (Matrix: TypeAlias = "npt.NDArray[...]")
        home = next(
            module.__name__
            for module in list(sys.modules.values())
            if ours(getattr(module, "__name__", "")) and vars(module).get(annotation) == value
        )
        value = eval(value, namespace_of(home), vars(builtins))
    return value


def _resolve_methods(cls: type) -> None:
    for member in list(vars(cls).values()):
        target = member.fget if isinstance(member, property) else member
        _resolve(getattr(target, "__func__", target))


def _defining_module(cls: type) -> str:
    """The module whose source has ``class <name>`` for ``cls`` (its ``__module__`` is public)."""
    pattern = re.compile(rf"^class {cls.__name__}\b", re.M)
    for module in list(sys.modules.values()):
        name, file = getattr(module, "__name__", ""), getattr(module, "__file__", None)
        if (
            ours(name)
            and name not in PUBLIC
            and vars(module).get(cls.__name__) is cls
            and file
            and pattern.search(Path(file).read_text("utf-8"))
        ):
            return str(name)
    raise LookupError(cls)


def build(out: Path) -> list[str]:
    """Write the reference into ``out``; return pdoc's warnings (empty: a clean build)."""
    import pdoc  # noqa: PLC0415 - the test extra's, only here
    import pdoc.doc  # noqa: PLC0415
    import pdoc.doc_ast  # noqa: PLC0415

    spaces = [importlib.import_module(space) for space in PUBLIC]
    for value in [getattr(space, name) for space in spaces for name in space.__all__]:
        if inspect.isclass(value):
            _resolve_methods(value)
            value.__rwt_source_module__ = _defining_module(value)  # type: ignore[attr-defined]
        elif callable(value):
            _resolve(value)

    plain_source = pdoc.doc_ast.get_source

    def source_of(obj: Any) -> str:
        module = getattr(obj, "__rwt_source_module__", None)
        if inspect.isclass(obj) and module is not None:
            public = obj.__module__
            try:
                obj.__module__ = module
                return plain_source(obj)
            finally:
                obj.__module__ = public
        return plain_source(obj)

    plain_resolve = pdoc.doc.resolve_annotations

    def resolve_in_home(
        annotations: dict[str, Any], module: Any, localns: Any, fullname: str
    ) -> dict[str, Any]:
        space = getattr(module, "__name__", "")
        cls = getattr(module, fullname.removeprefix(f"{space}."), None)
        home = getattr(cls, "__rwt_source_module__", None)
        if space in PUBLIC and home is not None:  # a class's attributes, in its own module
            module = sys.modules[home]
            namespace_of(home)  # its TYPE_CHECKING names, as pdoc would find them
        return plain_resolve(annotations, module, localns, fullname)

    pdoc.doc_ast.get_source = source_of
    pdoc.doc.resolve_annotations = resolve_in_home
    pdoc.render.configure(docformat="google", footer_text="rwt " + spaces[0].__version__)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # the namespaces by name: pdoc finds only the submodules __all__ lists
        pdoc.pdoc(*PUBLIC, output_directory=out)
    return [str(warning.message) for warning in caught]


def main() -> None:
    """``python -m tests.docs.api_reference OUT``: build, print warnings, exit 1 on any."""
    out = Path(sys.argv[1] if sys.argv[1:] else "apidocs")
    problems = build(out)
    for problem in problems:
        print(f"warning: {problem}", file=sys.stderr)
    print(f"{out / 'rwt.html'}: {len(problems)} warnings")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
