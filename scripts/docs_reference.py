"""The documentation's reference pages, generated from the code so that they cannot drift from it: the scene schema
from the scene dataclasses' field metadata (unit, meaning, choices, range, default), the command line from the
CLI's argparse parser.

MkDocs runs it as a hook (``hooks:`` in mkdocs.yml): ``on_files`` adds the pages ``reference/scene.md`` and
``reference/cli.md`` to the build, so they exist only in the built site. ``python scripts/docs_reference.py DIR``
writes them to DIR, to read them without building the site.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

PAGES = {"reference/scene.md": "scene_reference", "reference/cli.md": "cli_reference"}


def cli_parser() -> argparse.ArgumentParser:
    """The finrft command's parser (the one place that names where it lives)."""
    from finrft.cli import build_parser

    return build_parser()


def scene_classes() -> dict[str, type]:
    """The scene kinds, each a frozen dataclass of sections, with the commands that read them: every kind
    registered (`finrft.scene.register_scene`; importing finrft registers the experiments')."""
    import finrft  # noqa: F401  (registers the experiments' scene kinds)
    from finrft.scene import scene_kinds

    return {kind.title: kind.cls for kind in scene_kinds()}


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _value(value: Any) -> str:
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, (list, tuple)):
        return "`[" + ", ".join(f'"{v}"' if isinstance(v, str) else repr(v) for v in value) + "]`"
    return f"`{value!r}`"


def _range(meta: dict[str, Any]) -> str:
    choices = meta.get("choices") or ()
    if callable(choices):
        choices = choices()
    if choices:
        return ", ".join(f"`{c}`" for c in choices)
    low, high = meta.get("minimum"), meta.get("maximum")
    exclusive = meta.get("exclusive", True)
    parts = []
    if low is not None:
        parts.append(f"{'>' if exclusive else '≥'} {low:g}")
    if high is not None:
        parts.append(f"≤ {high:.6g}" + (f" ({meta['why_maximum']})" if meta.get("why_maximum") else ""))
    if meta.get("least") is not None:
        parts.append(f"0 or magnitude ≥ {meta['least']:g}")
    if meta.get("used_by"):
        selector, values = meta["used_by"]
        parts.append(f"only with {selector} = " + " or ".join(f"`{v}`" for v in values))
    return ", ".join(parts)


def _section_default(field: dataclasses.Field) -> Any:
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def scene_reference() -> str:
    lines = ["# Scene reference", "",
             "Generated from the scene schema (the sections of `finrft/scene.py` and of each experiment's module in "
             "`finrft/experiments/`, each field's metadata) when the documentation is built: it is the code's own "
             "list of keys. A scene file is TOML in SI units, but for `medium.zeta`, in N/cm³ as the literature gives it; "
             "a number may carry a unit suffix that fits its key's unit (`\"90deg\"`, `\"5mm\"`, `\"6e5 N/m3\"`), "
             "converted to the key's unit. A key it leaves out takes the default below (a preset, `finrft scene "
             "--dump NAME`, sets many of them); a key its entry's kind, profile or law does not use (\"only with\") "
             "is refused unless left at its default. On the command line any key is `--set SECTION.KEY=VALUE`.", ""]
    for title, cls in scene_classes().items():
        lines += [f"## {title}", ""]
        if cls.__doc__:
            lines += [" ".join(cls.__doc__.split()), ""]
        from finrft.schema import arrays, sections
        many = arrays(cls)
        for section in dataclasses.fields(cls):
            # An array of tables ([[drive]]): zero or more entries, each with the keys of its section.
            value = sections(cls)[section.name]() if section.name in many else _section_default(section)
            heading = f"[[{section.name}]]` (zero or more; `--set {section.name}.N.KEY=VALUE`, N from 0)" \
                if section.name in many else f"[{section.name}]`"
            lines += [f"### `{heading}", "",
                      "| key | unit | default | allowed | meaning |", "|---|---|---|---|---|"]
            for f in dataclasses.fields(value):
                meta = dict(f.metadata)
                lines.append(f"| `{f.name}` | {_cell(meta.get('unit', ''))} | {_cell(_value(getattr(value, f.name)))} "
                             f"| {_cell(_range(meta))} | {_cell(meta.get('doc', ''))} |")
            lines.append("")
    return "\n".join(lines)


def _expand(action: argparse.Action, prog: str) -> str:
    """An option's help as ``--help`` prints it (argparse's %(default)s and friends filled in)."""
    text = action.help or ""
    if "%" not in text:
        return text
    params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
    params["prog"] = prog
    for key in ("choices",):
        if params.get(key) is not None:
            params[key] = ", ".join(map(str, params[key]))
    try:
        return text % params
    except (KeyError, TypeError, ValueError):
        return text


def _flags(action: argparse.Action) -> str:
    names = ", ".join(f"`{o}`" for o in action.option_strings) or f"`{action.metavar or action.dest}`"
    if action.nargs != 0 and action.option_strings:
        if action.choices:
            names += " " + "|".join(map(str, action.choices))
        else:
            names += f" {action.metavar or action.dest.upper()}"
    return names


def _subcommands(parser: argparse.ArgumentParser) -> tuple[argparse._SubParsersAction | None, dict[str, str]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action, {a.dest: a.help or "" for a in action._choices_actions}
    return None, {}


def _command(name: str, parser: argparse.ArgumentParser, summary: str, lines: list[str]) -> None:
    sub, helps = _subcommands(parser)
    lines += [f"## `{name}`", ""]
    if summary:
        lines += [summary[0].upper() + summary[1:] + ".", ""]
    if parser.description:
        lines += [" ".join(parser.description.split()), ""]
    lines += ["```text", parser.format_usage().strip(), "```", ""]
    options = [a for a in parser._actions if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
               and a.help is not argparse.SUPPRESS]
    if options:
        lines += ["| argument | meaning |", "|---|---|"]
        lines += [f"| {_cell(_flags(a))} | {_cell(_expand(a, parser.prog))} |" for a in options]
        lines.append("")
    if parser.epilog:
        lines += [" ".join(parser.epilog.split()), ""]
    if sub is not None:
        for child, child_parser in sub.choices.items():
            _command(f"{name} {child}", child_parser, helps.get(child, ""), lines)


def cli_reference() -> str:
    parser = cli_parser()
    lines = ["# Command reference", "",
             "Generated from the command's own parser when the documentation is built: the same text as "
             "`finrft COMMAND --help`.", ""]
    _command("finrft", parser, "", lines)
    return "\n".join(lines)


def on_files(files: Any, config: Any) -> Any:
    """MkDocs hook: add the generated pages to the build."""
    from mkdocs.structure.files import File

    for uri, builder in PAGES.items():
        files.append(File.generated(config, uri, content=globals()[builder]()))
    return files


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description="Write the documentation's generated reference pages (the scene "
                                     "keys, the commands) to a folder, without building the site.")
    parser.add_argument("out", nargs="?", default="reference", metavar="DIR",
                        help="the folder to write scene.md and cli.md to (default: %(default)s)")
    out = Path(parser.parse_args(argv).out)
    for uri, builder in PAGES.items():
        path = out / Path(uri).name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(globals()[builder]())
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
