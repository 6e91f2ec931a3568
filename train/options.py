"""A trainer's config as a command line and as config.json.

A config is a dataclass. Each plain field is one command-line option (:func:`opt`: its
default and ``--help`` text; ``foo_bar`` becomes ``--foo-bar``). A group field (:func:`group`)
holds a frozen dataclass of settings whole, such as :class:`envs.four_finger.RewardSettings`,
and names the fields of it that the command line sets (:class:`Flag`); the trainer passes the
group on to the env as it is. :func:`options` lists a config's options in ``--help`` order
(:class:`Option`: the name, which is also the option's key in a flat config.json, and where
its value sits), and everything here works from that list:

- :func:`build_parser`: the argparse parser (one flat option per :class:`Option`);
- :func:`from_options`: a config from option values by name (a parsed command line);
- :func:`from_saved`: a config from its config.json, nested (groups as objects, what
  :func:`to_json` writes) or flat (every option by name at the top level, as configs were
  before their groups), unknown keys ignored;
- :func:`get_option`, :func:`set_options`, :func:`flat`: options read and set by name;
- :func:`record_options`: options changed in a saved config.json, in the layout it has;
- :func:`saved_value`: one value of a saved config.json of either layout, by name.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stability.cli import ArgumentParser

__all__ = [
    "Flag",
    "Option",
    "build_parser",
    "flat",
    "from_options",
    "from_saved",
    "get_option",
    "group",
    "opt",
    "options",
    "record_options",
    "saved_value",
    "set_options",
    "to_json",
]


def opt(default: Any, help: str, **kw: Any) -> Any:
    """A dataclass field with its ``--help`` text (and argparse extras such as choices)."""
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata={"help": help, **kw})
    return field(default=default, metadata={"help": help, **kw})


@dataclass(frozen=True)
class Flag:
    """The command-line option of one field of a settings group: its ``--help`` text, its
    ``choices``, and its ``name`` where that differs from the field's (the option
    ``--privileged-critic`` sets ``ObservationSettings.privileged``)."""

    help: str
    choices: tuple[Any, ...] | None = None
    name: str | None = None


def group(default: Any, **flags: Flag) -> Any:
    """A dataclass field holding the settings group ``default`` (a frozen dataclass, shared
    by every config made with it) whole; the group's fields named in ``flags`` are
    command-line options, listed in ``--help`` in that order."""
    return field(default_factory=lambda: default, metadata={"flags": flags})


@dataclass(frozen=True)
class Option:
    """One command-line option of a config: ``name`` (``foo_bar`` for ``--foo-bar``; its key in
    a flat config.json), ``path`` (the field, ``("seed",)``, or a group and its field,
    ``("reward", "drop_weight")``), the ``default``, the field's annotation ``type`` (a
    string such as ``"float"`` or ``"list[int]"``), ``help`` and ``choices``."""

    name: str
    path: tuple[str, ...]
    default: Any
    type: str
    help: str
    choices: tuple[Any, ...] | None = None


def _default(f: dataclasses.Field) -> Any:
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def options(cls: type) -> list[Option]:
    """The command-line options of the config dataclass ``cls``, in ``--help`` order: its
    plain fields, and within each group field the fields its :class:`Flag` s name."""
    out = []
    for f in dataclasses.fields(cls):
        default = _default(f)
        if "flags" not in f.metadata:
            choices = f.metadata.get("choices")
            out.append(Option(f.name, (f.name,), default, str(f.type), f.metadata["help"], choices))
            continue
        types = {g.name: str(g.type) for g in dataclasses.fields(default)}
        for name, flag in f.metadata["flags"].items():
            out.append(
                Option(
                    flag.name or name,
                    (f.name, name),
                    getattr(default, name),
                    types[name],
                    flag.help,
                    flag.choices,
                )
            )
    return out


def _type_of(annotation: str) -> tuple[Callable[[str], Any], bool]:
    """The scalar argparse ``type`` of a field's annotation and whether it is a list."""
    if annotation.startswith("list["):
        return {"list[int]": int, "list[float]": float}.get(annotation, str), True
    for name, conv in (("bool", bool), ("int", int), ("float", float)):
        if annotation == name:
            return conv, False
    return str, False


def build_parser(
    cls: type,
    prog: str = "python -m train.ppo",
    description: str | None = None,
    epilog: str | None = None,
) -> argparse.ArgumentParser:
    """An argparse parser generated from the config dataclass ``cls`` (:func:`options`).

    Each option ``foo_bar`` becomes ``--foo-bar`` with its help and choices, ``dest`` its
    name; bools become ``--x/--no-x``, lists take several values. Errors print one line
    (:class:`stability.cli.ArgumentParser`) and exit with status 2.
    """
    p = ArgumentParser(
        prog=prog,
        description=description,
        epilog=epilog,
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    for o in options(cls):
        flag = "--" + o.name.replace("_", "-")
        conv, is_list = _type_of(o.type)
        kw: dict[str, Any] = {"help": o.help, "default": o.default, "dest": o.name}
        if o.choices is not None:
            kw["choices"] = o.choices
        if conv is bool:
            p.add_argument(flag, action=argparse.BooleanOptionalAction, **kw)
        elif is_list:
            p.add_argument(flag, type=conv, nargs="+", metavar="N" if conv is int else None, **kw)
        else:
            p.add_argument(flag, type=conv, **kw)
    return p


def _assign(cfg: Any, changes: Iterable[tuple[tuple[str, ...], Any]], top: dict[str, Any]) -> Any:
    """``cfg`` with each ``(path, value)`` of ``changes`` set, and the plain fields ``top``."""
    groups: dict[str, dict[str, Any]] = {}
    for path, value in changes:
        if len(path) == 1:
            top[path[0]] = value
        else:
            groups.setdefault(path[0], {})[path[1]] = value
    for g, values in groups.items():
        top[g] = dataclasses.replace(getattr(cfg, g), **values)
    return dataclasses.replace(cfg, **top)


def set_options(cfg: Any, values: Mapping[str, Any], **fields: Any) -> Any:
    """``cfg`` with the options ``values`` (name -> value) and the plain ``fields`` set;
    KeyError for a name that is not an option of ``cfg``."""
    where = {o.name: o.path for o in options(type(cfg))}
    return _assign(cfg, ((where[k], v) for k, v in values.items()), dict(fields))


def from_options(cls: type, values: Mapping[str, Any]) -> Any:
    """A ``cls`` config from option values by name (``vars()`` of a parsed command line);
    options missing from ``values`` keep their defaults, names that are not options of
    ``cls`` are ignored."""
    known = {o.name for o in options(cls)}
    return set_options(cls(), {k: v for k, v in values.items() if k in known})


def from_saved(cls: type, saved: Mapping[str, Any]) -> Any:
    """A ``cls`` config from a saved config.json: a group saved as an object sets its fields
    (the layout :func:`to_json` writes), a key that names an option sets that option (a flat
    config.json, from before the groups); the rest (``task``, step marks, retired options) is
    ignored. What the file lacks keeps its default."""
    cfg = cls()
    nested = [
        f.name
        for f in dataclasses.fields(cls)
        if "flags" in f.metadata and isinstance(saved.get(f.name), Mapping)
    ]
    changes: list[tuple[tuple[str, ...], Any]] = []
    for g in nested:
        names = {x.name for x in dataclasses.fields(getattr(cfg, g))}
        changes += [((g, k), v) for k, v in saved[g].items() if k in names]
    changes += [
        (o.path, saved[o.name]) for o in options(cls) if o.name in saved and o.path[0] not in nested
    ]
    return _assign(cfg, changes, {})


def get_option(cfg: Any, name: str) -> Any:
    """The value of option ``name`` of ``cfg``; KeyError for a name that is not one."""
    path = {o.name: o.path for o in options(type(cfg))}[name]
    value = getattr(cfg, path[0])
    return getattr(value, path[1]) if len(path) == 2 else value


def flat(cfg: Any) -> dict[str, Any]:
    """Every option of ``cfg`` by name (the keys of a flat config.json)."""
    return {o.name: get_option(cfg, o.name) for o in options(type(cfg))}


def to_json(cfg: Any, **extra: Any) -> str:
    """config.json's text for ``cfg``: ``extra`` first (e.g. ``task``), then the fields,
    groups as objects of all their fields."""
    return json.dumps({**extra, **dataclasses.asdict(cfg)}, indent=2) + "\n"


def record_options(path: Path, cfg: Any, names: Iterable[str], **marks: Any) -> None:
    """Write the options ``names`` of ``cfg`` (and the keys ``marks``, e.g. the step a
    fine-tune starts at) into the saved config.json ``path``, in the layout it has: a flat
    file gets them by name at the top, a nested one (:func:`to_json`) at their places."""
    saved = json.loads(path.read_text())
    where = {o.name: o.path for o in options(type(cfg))}
    nested = any(isinstance(saved.get(p[0]), Mapping) for p in where.values() if len(p) == 2)
    for name in names:
        p = where[name]
        value = get_option(cfg, name)
        if nested and len(p) == 2:
            saved.setdefault(p[0], {})[p[1]] = value
        else:
            saved[name] = value
    path.write_text(json.dumps({**saved, **marks}, indent=2) + "\n")


def saved_value(saved: Mapping[str, Any], name: str) -> Any:
    """The value of ``name`` in a saved config.json of either layout, ``None`` when it has
    none: a top-level key, a dotted path (``"reward.drop_weight"``), or the field ``name``
    of one of its groups (``"drop_weight"`` in a nested file)."""
    if name in saved:
        return saved[name]
    head, _, rest = name.partition(".")
    if rest and isinstance(saved.get(head), Mapping):
        return saved[head].get(rest)
    found = [g[name] for g in saved.values() if isinstance(g, Mapping) and name in g]
    return found[0] if found else None
