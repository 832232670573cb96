"""Sphinx extension: the reference pages of the site, generated from the code at each build.

On ``builder-inited`` it writes ``docs/_generated/*.rst`` (not kept in git) from:

* ``cli.rst``: :func:`pneumatic_unload.app.cli.build_parser` (every sub-command, the batch
  ones of :mod:`pneumatic_unload.app.batch_cli` included, and every option with its help,
  default and choices);
* ``nodes.rst``: :data:`pneumatic_unload.config.nodes.NODES` and
  :func:`~pneumatic_unload.config.nodes.node_parameters` (every parameter of every node, from
  the field metadata), each node module's docstring (its topics, services, action) and the
  node's parameter file (:func:`~pneumatic_unload.config.nodes.yaml_text`);
* ``interfaces.rst``: the package's topics
  (:data:`pneumatic_unload.nodes.recorder.PACKAGE_TOPICS`) and the ``.msg``/``.action``
  files under ``pneumatic_unload_msgs/``, included verbatim;
* ``json.rst``: the document ``analyze --json`` prints
  (:data:`pneumatic_unload.analysis.output.ANALYZE_JSON_KEYS`), the fields of
  :class:`pneumatic_unload.estimation.UnloadResult` with their ``#:`` comments, and the keys
  :func:`pneumatic_unload.analysis.output.unload_json` adds
  (:data:`~pneumatic_unload.analysis.output.UNLOAD_JSON_KEYS`);
* ``api.rst``: ``automodule`` of the library's public modules (:data:`API_MODULES`);
* ``architecture.rst``: the layers of ``pneumatic_unload/test/test_layout.py`` (``LAYERS``,
  with its comments) and the modules of each part.

A file is rewritten only when its text changes, so that an unchanged page is not rebuilt.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib.util
import io
import json
import pkgutil
import re
import tokenize
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType
from typing import Any

from sphinx.application import Sphinx
from sphinx.pycode import ModuleAnalyzer

PKG = "pneumatic_unload"
#: The library modules documented with ``automodule`` on the API page.
API_MODULES: tuple[str, ...] = (
    "pneumatic_unload.physics",
    "pneumatic_unload.real_gas",
    "pneumatic_unload.charge",
    "pneumatic_unload.io",
    "pneumatic_unload.estimation",
    "pneumatic_unload.config",
    "pneumatic_unload.model",
    "pneumatic_unload.curvefit.fitting",
    "pneumatic_unload.uncertainty.budget",
    "pneumatic_unload.discrepancy",
    "pneumatic_unload.testline",
    "pneumatic_unload.fit",
    "pneumatic_unload.selection",
    "pneumatic_unload.selection.evidence",
    "pneumatic_unload.selection.averaging",
    "pneumatic_unload.model.candidates",
    "pneumatic_unload.estimation.final_fit",
)
#: The generated pages, in the order of the site's table of contents.
PAGES: tuple[str, ...] = ("cli", "nodes", "interfaces", "json", "api", "architecture")

_SPECIAL = re.compile(r"([\\`*_|\[\]])")


def esc(text: str) -> str:
    """``text`` as reStructuredText that renders it literally (one paragraph)."""
    text = " ".join(str(text).split())
    text = _SPECIAL.sub(r"\\\1", text)
    if text[:1] in "-+#:." or re.match(r"\d+[.)] ", text):
        text = "\\" + text  # not a list item or a directive
    return text


def literal(value: Any) -> str:
    """A value as inline literal text."""
    return f"``{value}``" if str(value).strip() else "``''``"


def heading(title: str, char: str) -> list[str]:
    """An underlined section title."""
    return [title, char * len(title), ""]


def indent(lines: Iterable[str], n: int = 3) -> list[str]:
    """Lines indented by n spaces (blank lines kept blank)."""
    pad = " " * n
    return [pad + ln if ln.strip() else "" for ln in lines]


def code_block(text: str, language: str = "text") -> list[str]:
    """A code block holding ``text`` verbatim."""
    return [f".. code-block:: {language}", "", *indent(text.rstrip("\n").splitlines()), ""]


def list_table(header: list[str], rows: list[list[str]], widths: str = "auto") -> list[str]:
    """A list-table of already-escaped cells."""
    out = [".. list-table::", "   :header-rows: 1", f"   :widths: {widths}", ""]
    for row in [header, *rows]:
        out.append(f"   * - {row[0]}")
        out += [f"     - {cell}" for cell in row[1:]]
    out.append("")
    return out


# ----------------------------------------------------------------------------- the CLI
def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The sub-command parsers of ``parser`` (empty without sub-commands)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _subcommand_help(parser: argparse.ArgumentParser) -> dict[str, str]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def cli_commands() -> dict[str, argparse.ArgumentParser]:
    """Every command of ``pneumatic-unload`` by its full name ('analyze', ...), nested
    sub-commands as 'a b'."""
    from pneumatic_unload.app.cli import build_parser

    out: dict[str, argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        for name, sub in _subcommands(parser).items():
            out[f"{prefix}{name}"] = sub
            walk(sub, f"{prefix}{name} ")

    walk(build_parser(), "")
    return out


#: Width of the usage lines [characters] (argparse's default follows the terminal).
USAGE_WIDTH = 88


def _formatter(parser: argparse.ArgumentParser) -> argparse.HelpFormatter:
    return parser.formatter_class(prog=parser.prog, width=USAGE_WIDTH)


def _usage(parser: argparse.ArgumentParser) -> str:
    """``parser``'s usage at :data:`USAGE_WIDTH` (the same on every machine)."""
    fmt = _formatter(parser)
    fmt.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups)
    return fmt.format_help()


def _invocation(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    return _formatter(parser)._format_action_invocation(action)


def _option_lines(parser: argparse.ArgumentParser, action: argparse.Action) -> list[str]:
    """An ``option`` directive: the help (as ``--help`` prints it, %-formats expanded), then
    whether it is required, its choices, default and number of values."""
    shown = action.help and action.help != argparse.SUPPRESS
    body = esc(_formatter(parser)._expand_help(action)) if shown else ""
    facts = []
    if action.required and action.option_strings:  # (a positional always is)
        facts.append("Required.")
    if action.choices is not None and not isinstance(action, argparse._SubParsersAction):
        facts.append("Choices: " + ", ".join(literal(c) for c in action.choices) + ".")
    plain_flag = isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction))
    if action.default not in (None, argparse.SUPPRESS) and not plain_flag \
            and action.option_strings:
        facts.append(f"Default: {literal(action.default)}.")
    if action.nargs in ("+", "*"):
        facts.append("Takes several values." if action.nargs == "+" else
                     "Takes any number of values.")
    help_text = body + ("." if body and facts and body[-1] not in ".)" else "")
    text = " ".join(x for x in [help_text, *facts] if x)
    return [f".. option:: {_invocation(parser, action)}", "", *indent([text]), ""]


def cli_page() -> str:
    """The command-line reference, from the argument parser."""
    from pneumatic_unload.app.cli import build_parser

    top = build_parser()
    helps = _subcommand_help(top)
    lines = [".. _cli:", "", *heading("Command line: pneumatic-unload", "="),
             "Generated from :func:`pneumatic_unload.app.cli.build_parser` at each build of this "
             "site: what ``pneumatic-unload COMMAND --help`` prints, in full.", "",
             esc(top.description or ""), "", *code_block(_usage(top)),
             *heading("Commands", "-")]
    commands = cli_commands()
    for name in commands:
        short = helps.get(name.split()[-1], "")
        lines.append(f"* :ref:`pneumatic-unload {name} <cli-{name.replace(' ', '-')}>`: "
                     f"{esc(short)}")
    lines.append("")
    for name, parser in commands.items():
        lines += [f".. _cli-{name.replace(' ', '-')}:", "",
                  *heading(f"pneumatic-unload {name}", "-")]
        short = helps.get(name.split()[-1], "")
        if short:
            lines += [esc(short[:1].upper() + short[1:]) + ".", ""]
        if parser.description:
            if isinstance(parser.formatter_class, type) and issubclass(
                    parser.formatter_class, argparse.RawDescriptionHelpFormatter):
                lines += code_block(parser.description)
            else:
                lines += [esc(parser.description), ""]
        lines += code_block(_usage(parser))
        if parser.epilog:
            lines += [esc(parser.epilog), ""]
        lines += [f".. program:: pneumatic-unload {name}", ""]
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            lines += _option_lines(parser, action)
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- the nodes
def _json_default(spec: Any) -> str:
    return "unset" if spec.default is None else literal(json.dumps(spec.default))


def nodes_page() -> str:
    """Every node: what it does, its topics (the module docstring) and every parameter."""
    from pneumatic_unload.config import nodes

    lines = [".. _nodes:", "", *heading("Nodes and their parameters", "="),
             "Generated from :mod:`pneumatic_unload.config.nodes` (the one list the nodes "
             "declare, ``NODE --help`` prints and ``config/NODE.yaml`` holds: names, types, "
             "defaults, units and ranges from the settings' field metadata) and from each "
             "node module's docstring. Run a node with ``ros2 run pneumatic_unload NODE`` "
             "(``--ros-args -p NAME:=VALUE`` or ``--params-file``). SI units.", ""]
    for node, what in nodes.NODES.items():
        lines.append(f"* :ref:`{node} <node-{node}>`: {esc(what)}")
    lines.append("")
    for node, what in nodes.NODES.items():
        specs = nodes.node_parameters(node)
        lines += [f".. _node-{node}:", "", *heading(node, "-"), esc(what[:1].upper() +
                                                                    what[1:]) + ".", ""]
        lines += [f".. automodule:: {PKG}.nodes.{node}", "   :no-members:", ""]
        lines += [f".. _node-{node}-parameters:", "",
                  *heading(f"Parameters of {node} ({len(specs)})", "~")]
        rows = [[literal(s.name), s.kind.replace("string_array", "string[]"),
                 _json_default(s), esc(s.description)] for s in specs.values()]
        lines += list_table(["Name", "Type", "Default", "Meaning, unit and range"], rows,
                            "20 8 14 58")
        lines += [f"The parameter file ``config/{node}.yaml`` "
                  f"(:func:`~pneumatic_unload.config.nodes.yaml_text`):", "",
                  *code_block(nodes.yaml_text(node), "yaml")]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------- the interfaces
def interfaces_page(srcdir: Path) -> str:
    """The package's topics (from the recorder's table) and its messages and action."""
    from pneumatic_unload.nodes.recorder import PACKAGE_TOPICS

    msg_root = srcdir.parent / "pneumatic_unload_msgs"
    lines = [".. _interfaces:", "", *heading("Topics, messages and the action", "="),
             *heading("Topics", "-"),
             "The package's topics as :data:`pneumatic_unload.nodes.recorder.PACKAGE_TOPICS` "
             "lists them (what the recorder records, with the QoS it subscribes with; all "
             "reliable). Which node publishes or subscribes to each, and the services and "
             "the action, are on each node's page: :ref:`nodes`.", ""]
    rows = [[literal(topic), literal(msgtype), durability, str(depth)]
            for topic, (msgtype, durability, depth) in PACKAGE_TOPICS.items()]
    lines += list_table(["Topic", "Message type", "Durability", "Depth"], rows)
    for kind, title in (("msg", "Messages"), ("action", "Action")):
        lines += heading(title, "-")
        lines += [f"The ``.{kind}`` files of the ``pneumatic_unload_msgs`` package "
                  f"(``pneumatic_unload_msgs/{kind}/``), verbatim.", ""]
        for path in sorted((msg_root / kind).glob(f"*.{kind}")):
            lines += [f".. _{kind}-{path.stem}:", "",
                      *heading(f"pneumatic_unload_msgs/{kind}/{path.stem}", "~"),
                      f".. literalinclude:: ../../pneumatic_unload_msgs/{kind}/{path.name}",
                      "   :language: text", ""]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------ the JSON output
def attribute_docs(cls: type) -> dict[str, str]:
    """The ``#:`` comment of each attribute of ``cls`` (as Sphinx's autodoc reads them)."""
    analyzer = ModuleAnalyzer.for_module(cls.__module__)
    docs = analyzer.find_attr_docs()
    return {name: " ".join(" ".join(text).split()) for (scope, name), text in docs.items()
            if scope == cls.__qualname__}


def unload_fields() -> list[tuple[str, str, str]]:
    """(name, type, meaning) of each field of :class:`UnloadResult` in the JSON output."""
    from pneumatic_unload.analysis.output import UNLOAD_JSON_DROPPED
    from pneumatic_unload.estimation import UnloadResult

    docs = attribute_docs(UnloadResult)
    return [(f.name, str(f.type), docs.get(f.name, "")) for f in dataclasses.fields(UnloadResult)
            if f.name not in UNLOAD_JSON_DROPPED]


def json_page() -> str:
    """The ``analyze --json`` document, key by key."""
    from pneumatic_unload.analysis import output

    lines = [".. _json:", "", *heading("JSON output of analyze", "="),
             "``pneumatic-unload analyze --json`` prints one JSON object. Generated from "
             ":data:`pneumatic_unload.analysis.output.ANALYZE_JSON_KEYS`, the fields of "
             ":class:`pneumatic_unload.estimation.UnloadResult` (their ``#:`` comments) and "
             ":data:`pneumatic_unload.analysis.output.UNLOAD_JSON_KEYS`. SI units; a number "
             "that is not known (NaN) is ``null``.", "", *heading("The document", "-")]
    rows = [[literal(k), esc(v)] for k, v in output.ANALYZE_JSON_KEYS.items()]
    lines += list_table(["Key", "Meaning"], rows, "25 75")
    lines += [".. _json-unload:", "", *heading("One unload", "-"),
              "Each item of ``unloads`` and ``published``: the fields of "
              ":class:`~pneumatic_unload.estimation.UnloadResult` (:func:`~pneumatic_unload."
              "output.unload_json`), then the keys it adds.", "",
              *heading("The result's fields", "~")]
    # (a #: comment is reStructuredText, as autodoc renders it)
    rows = [[literal(n), literal(t), d] for n, t, d in unload_fields()]
    lines += list_table(["Key", "Type", "Meaning"], rows, "22 10 68")
    lines += heading("Keys added by unload_json", "~")
    rows = [[literal(k), esc(v)] for k, v in output.UNLOAD_JSON_KEYS.items()]
    lines += list_table(["Key", "Meaning"], rows, "25 75")
    lines += status_section()
    return "\n".join(lines) + "\n"


def status_section() -> list[str]:
    """The status words of a result with their meaning, and the former words read as them."""
    from pneumatic_unload.estimation import types

    lines = [".. _json-statuses:", "", *heading("Statuses", "~"),
             "The ``status`` of a result (the text output's first line of each unload, the "
             "``UnloadEstimate`` message's ``STATUS_*`` value, the results database), from "
             ":data:`pneumatic_unload.estimation.types.STATUS_MEANINGS`:", ""]
    rows = [[literal(k), esc(types.STATUS_MEANINGS[k])] for k in types.STATUSES]
    lines += list_table(["Status", "Meaning"], rows, "18 82")
    lines += ["Former words, read as the current one from results databases written by "
              "older versions: " + ", ".join(f"{literal(old)} (now {literal(new)})"
                                             for old, new in types.STATUS_ALIASES.items())
              + ".", ""]
    return lines


# ------------------------------------------------------------------------------- the API
def api_page() -> str:
    """``automodule`` of each public module, with its members."""
    lines = [".. _api:", "", *heading("Library API", "="),
             "The library's public modules, from their docstrings (numpy style; SI units, "
             "each parameter's unit in brackets).", ""]
    for mod in API_MODULES:
        lines += [f".. _api-{mod.rsplit('.', 1)[-1]}:", "", *heading(mod, "-")]
        spec = importlib.util.find_spec(mod)
        if spec is not None and spec.origin is None:  # a namespace package: its modules
            lines += [f"The modules of the namespace package ``{mod}``.", ""]
            for sub in _part_modules(mod.split(".", 1)[1])[1:]:
                lines += [*heading(sub, "~"), f".. automodule:: {sub}", "   :members:", ""]
        else:
            lines += [f".. automodule:: {mod}", "   :members:", ""]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- the architecture
def _load_layout(srcdir: Path) -> ModuleType:
    path = srcdir.parent / "pneumatic_unload" / "test" / "test_layout.py"
    spec = importlib.util.spec_from_file_location("_docs_test_layout", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def layer_comments(path: Path) -> dict[str, str]:
    """The trailing comment of each entry of the ``LAYERS`` mapping in ``path``."""
    out: dict[str, str] = {}
    inside, key = False, None
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text(encoding="utf-8")).readline)
    for tok in tokens:
        if tok.type == tokenize.NAME and tok.string == "LAYERS" and tok.start[1] == 0:
            inside = True
        elif inside and tok.type == tokenize.STRING:
            key = tok.string.strip("\"'")
        elif inside and tok.type == tokenize.COMMENT and key is not None:
            out[key] = tok.string.lstrip("#").strip()
        elif inside and tok.type == tokenize.OP and tok.string == "}":
            break
        elif tok.type == tokenize.NL:
            key = None
    return out


def _summary(module: str) -> str:
    """First sentence of a module's docstring (reStructuredText), read without importing
    the module; '' without a docstring."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return ""
    doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding="utf-8"))) or ""
    first = " ".join(doc.split("\n\n")[0].split())
    m = re.match(r"(.+?\.)(\s|$)", first)
    return m.group(1) if m else first


def _part_modules(part: str) -> list[str]:
    """The modules of one part of the package (the part itself, and its submodules)."""
    name = f"{PKG}.{part}"
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        return [name]
    found: list[str] = []

    def walk(paths: list[str], prefix: str) -> None:  # (no import: pkgutil.walk_packages
        for info in pkgutil.iter_modules(paths, prefix):  # imports each subpackage)
            found.append(info.name)
            if info.ispkg:
                walk([str(Path(info.module_finder.path) / info.name.rsplit(".", 1)[-1])],
                     info.name + ".")

    walk(list(spec.submodule_search_locations), name + ".")
    return [name, *sorted(found)]


def architecture_page(srcdir: Path) -> str:
    """The layers of the package, lowest first, each part with its modules."""
    layout = _load_layout(srcdir)
    layers: dict[str, int] = layout.LAYERS
    comments = layer_comments(srcdir.parent / "pneumatic_unload" / "test" / "test_layout.py")
    lines = [".. _architecture:", "", *heading("Architecture: the layers", "="),
             "The package in layers, generated from ``LAYERS`` in "
             "``pneumatic_unload/test/test_layout.py`` "
             "(with its comments), the test that enforces them: a module imports only from "
             "its own layer or lower ones, never from a higher one, and there is no import "
             "cycle. The ROS-free core never imports ``rclpy`` or a message package; only "
             "the nodes (the highest layer) do. In italics, the comment of ``LAYERS``; then "
             "the first sentence of each module's docstring.", ""]
    for level in sorted(set(layers.values())):
        parts = [p for p, lv in layers.items() if lv == level]
        lines += heading(f"Layer {level}: {', '.join(parts)}", "-")
        for part in parts:
            mods = _part_modules(part)
            role = comments.get(part, "")
            text = " ".join(x for x in (f"*{esc(role)}*." if role else "",
                                        _summary(mods[0])) if x)
            lines += [f"``{PKG}.{part}``" + (f": {text}" if text else ""), ""]
            if len(mods) > 1:
                lines += [f"* ``{m}``" + (f": {t}" if (t := _summary(m)) else "")
                          for m in mods[1:]] + [""]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ the OPC UA address space
#: The included table of the OPC UA bridge's nodes (``.. include::`` of the cell how-to; not
#: a page of its own).
OPCUA_TABLE = "opcua_address_space.inc"


def opcua_table() -> str:
    """The address space of the OPC UA bridge's object, from
    :func:`pneumatic_unload.plc.address_space` (browse path, class and type, unit, meaning)."""
    from pneumatic_unload.plc import address_space

    rows = [[literal(path), esc(kind), esc(unit) if unit else "\\-", esc(doc)]
            for path, kind, unit, doc in address_space()]
    return "\n".join(list_table(["Browse path under Objects", "Node", "Unit (UNECE)",
                                  "Meaning"], rows, "26 22 14 38")) + "\n"


# ------------------------------------------------------------------------------ writing
def _write(path: Path, text: str) -> None:
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def generate(app: Sphinx) -> None:
    """Write the generated pages into ``<srcdir>/_generated``."""
    srcdir = Path(app.srcdir)
    out = srcdir / "_generated"
    out.mkdir(exist_ok=True)
    pages = {"cli": cli_page(), "nodes": nodes_page(), "interfaces": interfaces_page(srcdir),
             "json": json_page(), "api": api_page(), "architecture": architecture_page(srcdir)}
    assert tuple(pages) == PAGES
    for name, text in pages.items():
        _write(out / f"{name}.rst", text)
    _write(out / OPCUA_TABLE, opcua_table())
    for stale in set(out.glob("*.rst")) - {out / f"{n}.rst" for n in PAGES}:
        stale.unlink()


def setup(app: Sphinx) -> dict[str, Any]:
    """Register the generator."""
    app.connect("builder-inited", generate)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

