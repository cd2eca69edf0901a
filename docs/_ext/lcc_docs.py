"""Build-time generators of the lcc_synth documentation (called from ``docs/conf.py``).

Everything here turns an existing source of truth into pages, so that nothing is written twice:

* ``problem_reference.md`` from :func:`lcc_synth.schema.reference_markdown` (the text of
  ``problems/REFERENCE.md``) and ``problem_guide.md`` from ``problems/README.md``;
* ``cli.rst``: every command and flag, from the argument parser;
* ``api/<package>.rst``: one ``automodule`` per public module of every ``lcc_synth`` package
  (autodoc honours each module's ``__all__``);
* the gallery hooks: :func:`reset_argv` gives each example ``__file__``, ``__doc__`` and its
  ``--out`` directory under
  ``docs/_build/gallery-out`` (never the repository) and the quick arguments of
  ``tests/test_examples.py``; :func:`png_scraper` puts the PNGs an example wrote there on its
  page.

Generated files go to ``docs/_generated`` (git-ignored) and are rewritten only when their text
changes, so an incremental build stays incremental; a file there that this version does not
generate (a page of an older version, which Sphinx would read and warn about) is removed.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import shutil
import types
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
GENERATED = DOCS / "_generated"
GALLERY_OUT = DOCS / "_build" / "gallery-out"

#: Quick arguments of the slow examples (the same as tests/test_examples.py, which checks
#: that), besides --out.
EXAMPLE_ARGS = {
    "fig5_control_energy.py": ["--n-max", "8"],  # default 30: minutes in multiprecision
    "fig7_fig8_regions.py": ["--step", "0.5"],  # default: the paper's 1001 x 1001 grid
    # default: every controller; with the MPC and PI-with-saturation rows it took 31.7 of the
    # gallery's 42.2 s, without them 2.7 s (2026-12-02, 2-core machine at a load of 1); the
    # whole table is in docs/guide/benchmark.md
    "ring_sugiyama.py": ["--controllers", "all_hdv,follower_stopper,h2"],
    # default: 4 starts x 400 evaluations per bound, 12 for the lowest peak (minutes)
    "as_run_front.py": ["--starts", "1", "--maxfev", "30", "--cert-starts", "2"],
}

#: Links of the included Markdown files -> their pages in the documentation.
_LINKS = {
    "problems/REFERENCE.md": "problem_reference.md",
    "problems/README.md": "problem_guide.md",
    "REFERENCE.md": "problem_reference.md",
    "README.md": "problem_guide.md",
}


#: The files :func:`generate` wrote in this build (the others under GENERATED are stale).
_WRITTEN: set[Path] = set()


def _write(path: Path, text: str) -> None:
    _WRITTEN.add(path.resolve())
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def _relink(text: str, depth: str) -> str:
    """Markdown links to repository files -> documentation pages (or plain code)."""

    def sub(match: re.Match) -> str:
        label, target = match.group(1), match.group(2)
        path, _, anchor = target.partition("#")
        if path in _LINKS:
            page = depth + _LINKS[path]
            return f"[{label}]({page}#{anchor})" if anchor else f"[{label}]({page})"
        if path.startswith(("http://", "https://")):
            return match.group(0)
        return label  # another repository file (e.g. logs/README.md): its name, no link

    return re.sub(r"(?<!!)\[([^\]]+)\]\(([^)\s]+)\)", sub, text)


def problem_pages() -> None:
    """``problem_reference.md`` (the schema's reference) and ``problem_guide.md``."""
    from lcc_synth.schema import reference_markdown

    _write(GENERATED / "problem_reference.md", _relink(reference_markdown(), ""))
    guide = (ROOT / "problems" / "README.md").read_text()
    _write(GENERATED / "problem_guide.md", _relink(guide, ""))


def public_modules(package: str = "lcc_synth") -> dict[str, list[str]]:
    """Public modules per package: ``{package: [module, ...]}`` (no ``_private``, no
    ``__main__``), packages in import order."""
    pkg = importlib.import_module(package)
    out: dict[str, list[str]] = {package: []}
    for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."):
        last = info.name.rsplit(".", 1)[1]
        if last.startswith("_"):
            continue
        if info.ispkg:
            out[info.name] = []
        else:
            out[info.name.rsplit(".", 1)[0]].append(info.name)
    return out


def _automodule(name: str) -> list[str]:
    """``automodule`` of one module: the functions and classes of its ``__all__`` defined there
    (or, without ``__all__``, autodoc's public members), an ``autodata`` per constant, and a
    line linking the names it re-exports."""
    mod = importlib.import_module(name)
    lines = [f".. automodule:: {name}"]
    names = getattr(mod, "__all__", None)
    if names is None:
        return [*lines, "   :members:", ""]
    own, data, other = [], [], []
    for attr in names:
        obj = getattr(mod, attr, None)
        if isinstance(obj, types.ModuleType):
            other.append(f":mod:`{attr} <{obj.__name__}>`")
        elif not callable(obj):
            data.append(attr)
        elif obj.__module__ == name:
            own.append(attr)
        else:
            role = "class" if isinstance(obj, type) else "func"
            other.append(f":{role}:`{attr} <{obj.__module__}.{obj.__qualname__}>`")
    lines += [f"   :members: {', '.join(own)}" if own else "   :no-members:", ""]
    for attr in data:
        lines += [f".. autodata:: {name}.{attr}", "   :no-value:", ""]
    if other:
        lines += [f"Also here (defined elsewhere): {', '.join(other)}.", ""]
    return lines


def api_pages() -> None:
    """``api/<package>.rst``: the package's docstring and one section per module."""
    packages = public_modules()
    for package, modules in packages.items():
        lines = [f"``{package}``", "=" * (len(package) + 4), "", *_automodule(package)]
        for mod in modules:
            title = f"``{mod}``"
            # "~", not "-": the module docstrings' own "-" sections nest under the module
            lines += [title, "~" * len(title), "", *_automodule(mod)]
        _write(GENERATED / "api" / f"{package}.rst", "\n".join(lines))
    index = ["API reference", "=============", "",
             "Every public module, from its numpydoc docstrings (each module's ``__all__``).",
             "The flat API, :mod:`lcc_synth.api`, is the place to start.", "",
             ".. toctree::", "   :maxdepth: 1", ""]  # fmt: skip
    index += [f"   {package}" for package in packages]
    _write(GENERATED / "api" / "index.rst", "\n".join(index) + "\n")


def _rst_text(text: str) -> str:
    """Plain text (an argparse help) as rST text: every markup character escaped."""
    return re.sub(r"([\\*`|_<>\[\]])", r"\\\1", " ".join(text.split()))


def _parser_rst(parser, title: str, level: str) -> list[str]:
    lines = [title, level * len(title), ""]
    if parser.description:
        lines += [_rst_text(parser.description), ""]
    lines += ["::", "", *("    " + u for u in parser.format_usage().rstrip().splitlines()), ""]
    formatter = parser._get_formatter()
    for group in parser._action_groups:
        actions = [a for a in group._group_actions if a.help is not argparse.SUPPRESS
                   and not isinstance(a, argparse._SubParsersAction)]  # fmt: skip
        if not actions:
            continue
        lines += [f"**{group.title}**", ""]
        for action in actions:
            lines += [f"``{formatter._format_action_invocation(action)}``"]
            text = formatter._expand_help(action) if action.help else ""
            lines += [f"    {_rst_text(text)}" if text else "    (no help)", ""]
    return lines


def cli_rst() -> str:
    """The text of ``cli.rst``: every command of ``lcc-synth`` and every flag, from the argument
    parser (:func:`lcc_synth.cli.main.build_parser`), its help texts shown verbatim."""
    from lcc_synth.cli.main import build_parser

    parser = build_parser()
    lines = ["Command-line reference", "======================", "",
             "Every ``lcc-synth`` command and flag, generated at build time from the argument",
             "parser (:func:`lcc_synth.cli.main.build_parser`). Exit codes: 0 success, 1 a run",
             "that found a failure (e.g. a solver failure), 2 bad input (problem file or option),",
             "reported in one line naming the file and the field.", "",
             *_parser_rst(parser, "lcc-synth", "-")]  # fmt: skip
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        lines += _parser_rst(command, f"lcc-synth {name}", "-")
    return "\n".join(lines)


def cli_page() -> None:
    """Write ``cli.rst`` (:func:`cli_rst`)."""
    _write(GENERATED / "cli.rst", cli_rst())


def generate() -> None:
    """All generated pages (called by conf.py before Sphinx reads the sources); stale files of
    an older version are removed."""
    _WRITTEN.clear()
    cli_page()
    problem_pages()
    api_pages()
    for path in sorted(GENERATED.rglob("*"), reverse=True):  # files first, then empty dirs
        if path.is_file() and path.resolve() not in _WRITTEN:
            path.unlink()
        elif path.is_dir() and not any(path.iterdir()):
            path.rmdir()


# -- sphinx-gallery hooks (named by string in conf.py, so the config stays picklable) ----------


def _out_dir(src_file: str) -> Path:
    return GALLERY_OUT / Path(src_file).stem


def reset_argv(gallery_conf, script_vars) -> list[str]:
    """``sys.argv[1:]`` of an example in the gallery: its quick arguments and ``--out``.

    sphinx-gallery runs an example with ``__doc__ = ""`` and no ``__file__``; the examples use
    both (their ``argparse`` description, the ``problems/`` folder next to them), so this hook,
    which sphinx-gallery calls once the example's globals exist, gives them the values a
    ``python examples/NAME.py`` run has.
    """
    import ast

    src = Path(script_vars["src_file"])
    example_globals = script_vars.get("example_globals")
    if example_globals is not None:
        example_globals["__file__"] = str(src)
        example_globals["__doc__"] = ast.get_docstring(ast.parse(src.read_text()), clean=False)
    name = src.name
    out = _out_dir(script_vars["src_file"])
    shutil.rmtree(out, ignore_errors=True)  # a fresh directory: the PNGs found are this run's
    return [*EXAMPLE_ARGS.get(name, []), "--out", str(out)]


def png_scraper(block, block_vars, gallery_conf) -> str:
    """The PNGs the example wrote under its ``--out`` (sorted by name), as its figures."""
    from sphinx_gallery.scrapers import figure_rst

    out = _out_dir(block_vars["src_file"])
    seen = block_vars.setdefault("lcc_seen_pngs", set())
    pngs = sorted(p for p in out.rglob("*.png") if p not in seen) if out.is_dir() else []
    names = []
    for png, target in zip(pngs, block_vars["image_path_iterator"], strict=False):
        shutil.copyfile(png, target)
        seen.add(png)
        names.append(target)
    return figure_rst(names, gallery_conf["src_dir"])


def allow_exit_zero() -> None:
    """Let an example end with ``raise SystemExit(main())`` in the gallery, as on the command line.

    sphinx-gallery catches ``Exception`` only, so an example's ``SystemExit`` would stop Sphinx
    itself. This wraps the function that executes a code block (``sphinx_gallery.gen_rst.
    _exec_and_get_memory``, the one private name used here): exit code 0 or ``None`` ends the
    example normally; any other code becomes a ``RuntimeError``, a failed example, which fails
    the build (``abort_on_example_error``).
    """
    from sphinx_gallery import gen_rst

    inner = getattr(gen_rst, "_exec_and_get_memory", None)
    if inner is None:
        raise RuntimeError("sphinx_gallery.gen_rst._exec_and_get_memory is gone: update "
                           "docs/_ext/lcc_docs.py for this sphinx-gallery")  # fmt: skip
    if getattr(inner, "lcc_wrapped", False):
        return

    def wrapped(*args, **kwargs):
        try:
            return inner(*args, **kwargs)
        except SystemExit as exc:
            if exc.code not in (0, None):
                raise RuntimeError(f"the example exited with code {exc.code!r}") from exc
            return False, 0.0  # (is_last_expr, memory): no last expression to show

    wrapped.lcc_wrapped = True
    gen_rst._exec_and_get_memory = wrapped


# -- docstrings --------------------------------------------------------------------------------

_LITERAL = re.compile(r"(``.+?``|`[^`]+`_?)")


def escape_bars(app, what, name, obj, options, lines: list[str]) -> None:
    """``autodoc-process-docstring``: ``|x|`` in a docstring is an absolute value, not an rST
    substitution. Escapes ``|`` outside inline literals, roles and indented (literal) blocks."""
    literal_block = False
    block_indent = 0
    for i, line in enumerate(lines):
        stripped = line.lstrip()
        indent = len(line) - len(stripped)
        if literal_block:
            if stripped and indent <= block_indent:
                literal_block = False
            else:
                continue
        if "|" in line:
            parts = _LITERAL.split(line)
            lines[i] = "".join(p if j % 2 else p.replace("|", r"\|") for j, p in enumerate(parts))
        if line.rstrip().endswith("::") or stripped.startswith((".. code-block::", ".. math::")):
            literal_block, block_indent = True, indent


_ROLE_TYPES = {
    "func": ("function",), "class": ("class", "exception"), "exc": ("exception", "class"),
    "meth": ("method", "classmethod", "staticmethod"), "attr": ("attribute", "property"),
    "data": ("data",), "mod": ("module",), "obj": (),
}  # fmt: skip


def resolve_short_names(app, env, node, contnode):
    """``missing-reference``: a Python cross-reference by a short or partial name
    (``:class:`ConfigError``` in a module that imports it) links to the one documented object
    whose full name ends with it. Ambiguous or unknown names stay unresolved (a warning: the
    build runs nitpicky with ``-W``)."""
    from sphinx.util.nodes import make_refnode

    if node.get("refdomain") != "py":
        return None
    target = re.sub(r"\s+", "", node.get("reftarget", "")).lstrip("~.")  # wrapped lines
    if not target:
        return None
    objects = env.get_domain("py").objects
    here = node.get("py:module") or ""
    cls = node.get("py:class")
    candidates = [f"{here}.{cls}.{target}"] if cls else []
    candidates += [target]
    if node.get("reftype") in ("attr", "meth") and "." in target:
        candidates.append(target.rsplit(".", 1)[0])  # a dataclass field: its class
    for wanted in candidates:
        hits = [name for name in objects if name == wanted or name.endswith("." + wanted)]
        if not hits and "." in wanted:  # package.name re-exported from package.module.name
            prefix, last = wanted.rsplit(".", 1)
            hits = [n for n in objects if n.startswith(prefix + ".") and n.endswith("." + last)]
        kinds = _ROLE_TYPES.get(node.get("reftype"), ())
        if len(hits) > 1 and any(objects[n].objtype in kinds for n in hits):
            hits = [n for n in hits if objects[n].objtype in kinds]  # :func: -> a function
        if len(hits) > 1:  # prefer the objects nearest the referring module

            def shared(n):
                return len(os.path.commonprefix([n.split("."), here.split(".")]))

            best = max(shared(n) for n in hits)
            hits = [n for n in hits if shared(n) == best]
        if len(hits) == 1:
            entry = objects[hits[0]]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                                contnode, hits[0])  # fmt: skip
    return None
