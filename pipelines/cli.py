"""The command line of every stage, checked against the stage's schema before Hydra runs.

Hydra accepts ``+famly=gamma`` silently (a new key nobody reads: the stage re-runs everything
with its defaults) and turns a mistyped value into a traceback. Here each override is
checked against the stage's typed settings (:data:`pipelines.schemas.STAGE_SCHEMAS`) first:
an unknown key, with or without ``+``, and a value of the wrong type end the command with
one line naming the key (with the nearest known names) and exit status 2. ``--help`` prints
the stage's settings with their defaults and meanings, read from the schema's ``#:``
comments. Config groups (``family=``, ``paths.``, ``tracking.``, ``hydra.`` ...) are left to
Hydra, which knows them.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import re
import sys
import textwrap
import typing
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from pipelines import schemas

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
#: Hydra's flags that take a value (the value is not an override).
FLAGS_WITH_VALUE = {"--cfg", "-c", "--package", "-p", "--config-path", "-cp", "--config-name",
                    "-cn", "--config-dir", "-cd", "--experimental-rerun"}
#: Settings that select configurations by number: ``ninety`` is a typo, not a shape.
NUMERIC_SELECTORS = {"config.curve_angle_deg", "config.radius_mm"}


class CommandLineError(Exception):
    """An override the stage does not know, or a value of the wrong type."""


def config_groups() -> set[str]:
    """The config groups under ``conf/`` (their keys are Hydra's to check) and ``hydra``."""
    return {p.name for p in CONF_DIR.iterdir() if p.is_dir()} | {"hydra", schemas.WORKFLOW_GROUP}


def overrides_of(argv: Sequence[str]) -> list[str]:
    """The ``key=value`` overrides of a command line (Hydra's flags and their values left
    out)."""
    out: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
            continue
        if arg in FLAGS_WITH_VALUE:
            skip = True
            continue
        if arg.startswith("-"):
            continue
        out.append(arg)
    return out


def _typed_node(stage: str) -> DictConfig:
    node = schemas.schema_node(schemas.STAGE_SCHEMAS[stage])
    OmegaConf.set_struct(node, True)
    _open_free_mappings(node)
    return node


def _open_free_mappings(node: DictConfig) -> None:
    """Free mappings (``family_overrides``, ``auto_families`` ...) take any key."""
    for key in node:
        child = node._get_node(str(key))
        if not isinstance(child, DictConfig) or child._is_none() or child._is_missing():
            continue
        if child._metadata.object_type in (None, dict):
            OmegaConf.set_struct(child, False)
        else:
            _open_free_mappings(child)


def _near(name: str, known: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, sorted(set(known)), n=3, cutoff=0.6)
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""


def _unknown(stage: str, node: DictConfig, key: str, added: bool) -> CommandLineError:
    parts = key.split(".")
    parent: Any = node
    for i, part in enumerate(parts):
        if not isinstance(parent, DictConfig) or part not in parent.keys():
            where = ".".join(parts[:i])
            known = [str(k) for k in parent] if isinstance(parent, DictConfig) else []
            if not where:
                known += sorted(config_groups() - {"hydra"})
            plus = " ('+' adds keys only to free mappings such as family_overrides)" \
                if added else ""
            scope = f" under {where!r}" if where else ""
            return CommandLineError(
                f"{stage}: unknown setting {key!r}{scope}{_near(part, known)}{plus}; "
                f"python -m {module_of(stage)} --help lists the settings")
        parent = parent._get_node(part)
    return CommandLineError(f"{stage}: unknown setting {key!r}")


def module_of(stage: str) -> str:
    return "pipelines.run_all" if stage == "pipeline" else f"pipelines.{stage}"


def _values(override: Any) -> list[Any] | None:
    """The values an override sets (every choice of a sweep), or ``None`` where it cannot
    say (ranges, intervals, functions)."""
    from hydra.core.override_parser.types import ChoiceSweep

    value = override.value()
    if isinstance(value, ChoiceSweep):
        return list(value.list)
    if override.is_sweep_override():
        return None
    return [value]


def check_overrides(stage: str, argv: Sequence[str]) -> None:
    """Raise :class:`CommandLineError` for the first override ``stage`` cannot take."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import OverrideParseException

    lines = overrides_of(argv)
    if not lines:
        return
    try:
        parsed = OverridesParser.create().parse_overrides(lines)
    except OverrideParseException as err:
        raise CommandLineError(f"{stage}: {str(err).splitlines()[0]}") from None
    groups = config_groups()
    chosen: dict[str, str] = {}  # group -> the option the command line picks
    for ov in parsed:
        picked = ov.value()
        if ov.key_or_group in groups and isinstance(picked, str):
            chosen[ov.key_or_group] = picked
    for ov in parsed:
        key = ov.key_or_group
        head = key.split("/")[0].split(".")[0]
        if ov.is_delete() or head in groups:
            if not ov.is_delete() and head in CHECKED_GROUPS and "." in key:
                _check_group_key(stage, key, _values(ov), chosen.get(head))
            continue
        _check_setting(stage, ov)


def _check_setting(stage: str, ov: Any) -> None:
    """One override of the stage's own settings: a known key, a value of its type."""
    key = ov.key_or_group
    node = _typed_node(stage)
    if not _exists(node, key):
        raise _unknown(stage, node, key, ov.is_add())
    values = _values(ov)
    for value in values or []:
        node = _typed_node(stage)  # fresh: one choice of a sweep must not hide another
        try:
            OmegaConf.update(node, key, value, merge=True)
        except OmegaConfBaseException:
            raise CommandLineError(
                f"{stage}: {key}={value!r} is not {_expected_type(stage, key)}") from None
        if key in NUMERIC_SELECTORS:
            _check_numbers(stage, key, value)
        if key.startswith("overrides.") and isinstance(value, list):
            _check_stage_overrides(stage, key, value)


def _check_stage_overrides(stage: str, key: str, lines: list[Any]) -> None:
    """run_all's ``overrides.<stage>=[...]``: each line is checked as that stage's own
    command line would be, before anything runs."""
    inner = key.split(".", 1)[1]
    if inner not in schemas.STAGE_SCHEMAS:
        return
    try:
        check_overrides(inner, [str(line) for line in lines])
    except CommandLineError as err:
        raise CommandLineError(f"{stage}: in {key}: {err}") from None


# -- config groups ---------------------------------------------------------------------------

#: Groups whose options are closed sets of keys: a key none of the options has is a typo.
#: (``importer`` mappings are the user's own; ``experiment`` and ``hydra`` are not nodes.)
CHECKED_GROUPS = {"campaign", "effects", "family", "paths", "rig", "tracking"}


def _group_options(group: str, chosen: str | None) -> list[Any]:
    """The raw (unresolved) option files of ``group``: the chosen one, else all of them."""
    files = sorted((CONF_DIR / group).glob("*.yaml"))
    if chosen is not None and (CONF_DIR / group / f"{chosen}.yaml").exists():
        files = [CONF_DIR / group / f"{chosen}.yaml"]
    return [OmegaConf.to_container(OmegaConf.load(f), resolve=False) for f in files]


def _lookup(option: Any, parts: Sequence[str]) -> tuple[bool, Any]:
    """(found, value) of a dotted key in one option; a free mapping (``params: {}``) or a
    list on the way takes any key below it."""
    node = option
    for part in parts:
        if isinstance(node, list) or (isinstance(node, dict) and not node):
            return True, None
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _check_group_key(stage: str, key: str, values: list[Any] | None,
                     chosen: str | None) -> None:
    """``group.key=value``: the key must exist in the group's option (the one chosen on the
    command line, else any), and a value where every option holds a number (or true/false)
    must be one too."""
    group, *parts = key.split(".")
    options = _group_options(group, chosen)
    found = [value for ok, value in (_lookup(o, parts) for o in options) if ok]
    if not found:
        known = sorted({k for o in options for k in _keys_at(o, parts[:-1])})
        where = ".".join([group, *parts[:-1]])
        raise CommandLineError(
            f"{stage}: unknown setting {key!r} under {where!r}{_near(parts[-1], known)}; "
            f"the options of conf/{group}/ have {', '.join(known) or 'no such keys'}")
    for value in values or []:
        _check_group_value(stage, key, value, found)


def _keys_at(option: Any, parts: Sequence[str]) -> list[str]:
    ok, node = _lookup(option, parts) if parts else (True, option)
    return [str(k) for k in node if k != "defaults"] if ok and isinstance(node, dict) else []


def _check_group_value(stage: str, key: str, value: Any, defaults: list[Any]) -> None:
    scalars = [d for d in defaults if d is not None and not isinstance(d, dict | list | str)]
    if value is None or not scalars or len(scalars) != len(defaults):
        return
    if all(isinstance(d, bool) for d in scalars):
        if not isinstance(value, bool):
            raise CommandLineError(f"{stage}: {key}={value!r} is not true or false")
    elif all(isinstance(d, int | float) and not isinstance(d, bool) for d in scalars):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CommandLineError(f"{stage}: {key}={value!r} is not a number")


def _exists(node: DictConfig, key: str) -> bool:
    """``key`` names a setting of ``node``, or a key inside one of its free mappings."""
    parent: Any = node
    for part in key.split("."):
        if not isinstance(parent, DictConfig):
            return False
        if parent._metadata.object_type in (None, dict) and parent is not node:
            return True
        if part not in parent.keys():  # `in` alone misses a setting with no default
            return False
        parent = parent._get_node(part)
    return True


def _check_numbers(stage: str, key: str, value: Any) -> None:
    items = value if isinstance(value, list) else [value]
    for item in items:
        if item is None or (isinstance(item, int | float) and not isinstance(item, bool)):
            continue
        raise CommandLineError(
            f"{stage}: {key}={item!r} is not a number (a value, a list such as [15,90], "
            "or null for every one)")


def _field_type(stage: str, key: str) -> Any:
    cls: Any = schemas.STAGE_SCHEMAS[stage]
    hint: Any = None
    for part in key.split("."):
        if not dataclasses.is_dataclass(cls):
            return None
        hints = typing.get_type_hints(cls)
        hint = hints.get(part)
        cls = hint
    return hint


def _expected_type(stage: str, key: str) -> str:
    hint = _field_type(stage, key)
    names = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}
    if hint in names:
        return names[hint]
    return f"a {getattr(hint, '__name__', str(hint)).replace('typing.', '')}" if hint else \
        "of the setting's type"


# -- --help ----------------------------------------------------------------------------------

def _field_comments(cls: type) -> dict[str, str]:
    """``field -> meaning`` from the ``#:`` comment lines above each field in ``cls``'s
    source."""
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    out: dict[str, str] = {}
    pending: list[str] = []
    for line in source.splitlines()[1:]:
        text = line.strip()
        if text.startswith("#:"):
            pending.append(text[2:].strip())
            continue
        match = re.match(r"([A-Za-z_]\w*)\s*:", text)
        if match and pending:
            out[match.group(1)] = " ".join(pending)
        if not text.startswith("#"):
            pending = []
    return out


def _settings(cls: Any, prefix: str = "") -> Iterator[tuple[str, str, str]]:
    """(dotted name, default, meaning) of every setting of the schema ``cls``."""
    meanings: dict[str, str] = {}
    for base in reversed(cls.__mro__):
        if isinstance(base, type) and dataclasses.is_dataclass(base):
            meanings.update(_field_comments(base))
    defaults = schemas.schema_node(cls)
    for f in dataclasses.fields(cls):
        name = prefix + f.name
        child = defaults._get_node(f.name)
        if dataclasses.is_dataclass(f.type if isinstance(f.type, type) else None) or (
                isinstance(child, DictConfig) and child._metadata.object_type not in (None, dict)
                and dataclasses.is_dataclass(child._metadata.object_type)):
            nested = child._metadata.object_type if isinstance(child, DictConfig) else f.type
            about = meanings.get(f.name) or (inspect.getdoc(nested) or "").split("\n\n")[0]
            yield name, "", " ".join(about.split())
            yield from _settings(nested, name + ".")
            continue
        if OmegaConf.is_missing(defaults, f.name):
            shown = "(config group)"
        else:
            value = OmegaConf.to_container(defaults, resolve=False).get(f.name)  # type: ignore[union-attr]
            shown = "null" if value is None else str(value).lower() \
                if isinstance(value, bool) else str(value)
        yield name, shown, meanings.get(f.name, "")


def help_text(stage: str) -> str:
    cls = schemas.STAGE_SCHEMAS[stage]
    doc = inspect.getdoc(cls) or ""
    title = " ".join(doc.split("\n\n")[0].split()) if doc else stage
    lines = [f"python -m {module_of(stage)} [key=value ...]   ({title})", "",
             "Settings (default, then meaning):"]
    for name, default, meaning in _settings(cls):
        head = f"  {name} = {default}" if default else f"  {name}"
        lines.append(head)
        if meaning:
            lines += textwrap.wrap(meaning, width=96, initial_indent="      ",
                                   subsequent_indent="      ")
    groups = ", ".join(sorted(config_groups() - {"hydra"}))
    lines += ["", f"Config groups (conf/<group>/<name>.yaml, chosen as group=name): {groups}.",
              "A sweep: -m key=a,b. Hydra's own options: --hydra-help."]
    return "\n".join(lines)


def guard(stage: str, argv: Sequence[str] | None = None) -> None:
    """What every stage's ``__main__`` calls before Hydra: ``--help`` prints the settings and
    exits 0; an override the stage cannot take exits 2 with one line on stderr."""
    args = list(sys.argv[1:] if argv is None else argv)
    if "--help" in args or "-h" in args:
        print(help_text(stage))
        raise SystemExit(0)
    try:
        check_overrides(stage, args)
    except CommandLineError as err:
        print(str(err), file=sys.stderr)
        raise SystemExit(2) from None
