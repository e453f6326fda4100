"""Lookup of environments by name: the built-in domains, ``gym:<id>`` Gymnasium environments and
``minigrid:<id>`` MiniGrid layouts (the optional ``minigrid`` extra, imported only when such a
name is resolved).

Built-in domains are imported lazily (``"module:Class"``), so listing them costs nothing.

Trust model: ``gym:MODULE:Id-v0`` imports the Python module ``MODULE`` (running its code) so that
it can register ``Id-v0``, as ``gymnasium.make`` does. A name typed on the command line or passed
by a program is trusted like any Python the user runs. A name read from a file (a sweep config)
is not: such a file may import only the modules it lists in ``allow_imports``
(:func:`gym_module` finds the module a name would import).
"""

from __future__ import annotations

import difflib
import importlib
import json
from pathlib import Path

from adpart.envs.base import Domain
from adpart.errors import UnknownNameError

#: name -> "module:Class" of every built-in domain.
BUILTIN_DOMAINS: dict[str, str] = {
    "two-rooms": "adpart.envs.domains.two_rooms:TwoRooms",
    "four-rooms": "adpart.envs.domains.four_rooms:FourRooms",
    "three-floor": "adpart.envs.domains.three_floor:ThreeFloor",
    "three-floor-arm": "adpart.envs.domains.three_floor:ThreeFloorArm",
    "parr-maze": "adpart.envs.domains.parr_maze:ParrMaze",
    "taxi": "adpart.envs.domains.taxi:Taxi",
    "taxi-fickle": "adpart.envs.domains.taxi:FickleTaxi",
    "urban": "adpart.envs.domains.urban:Urban",
}

GYM_PREFIX = "gym:"
MINIGRID_PREFIX = "minigrid:"
#: The prefixes of environments resolved by an adapter rather than the plugin registry.
ADAPTER_PREFIXES = (GYM_PREFIX, MINIGRID_PREFIX)


def load_class(target: str) -> type:
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def domain_names() -> list[str]:
    return list(BUILTIN_DOMAINS)


def _gym_value(text: str, name: str = "", key: str = "") -> object:
    """A keyword value from a name: ``true``/``false`` (any case), ``none``, an int, a float,
    JSON (a value starting with ``[``, ``{`` or ``"``: a map as a list of strings,
    ``desc=["SFFF","FHFH","FFFH","HFFG"]``), ``@FILE`` (the value read from a file: JSON if it
    ends in ``.json``, else its non-empty lines as a list of strings), or text."""
    stripped = text.strip()
    if stripped[:1] in ("[", "{", '"'):
        try:
            return json.loads(stripped)
        except json.JSONDecodeError as exc:
            raise UnknownNameError(
                f"cannot read {key}={stripped!r} in {name!r} as JSON ({exc}): write a list of "
                'strings as ["SFFF","FHFH"], or give the value from a file as @FILE') from None
    if stripped.startswith("@"):
        return _file_value(stripped[1:], name, key)
    low = stripped.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("none", "null"):
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def _file_value(path: str, name: str, key: str) -> object:
    """The value of ``key=@path``: JSON from a ``.json`` file, else the file's non-empty lines."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise UnknownNameError(f"cannot read {key}=@{path} in {name!r}: {exc.strerror or exc}; "
                               "give a readable file (JSON, or one map row per line)") from None
    if path.endswith(".json"):
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise UnknownNameError(f"cannot read {key}=@{path} in {name!r}: {path} is not JSON "
                                   f"({exc})") from None
    return [line.strip() for line in text.splitlines() if line.strip()]


def _split_arguments(text: str) -> list[str]:
    """``key=value`` items of a bracket, split on the commas outside brackets and quotes."""
    items, depth, quoted, start = [], 0, False, 0
    for i, char in enumerate(text):
        if char == '"' and (i == 0 or text[i - 1] != "\\"):
            quoted = not quoted
        elif not quoted and char in "[{":
            depth += 1
        elif not quoted and char in "]}":
            depth -= 1
        elif not quoted and depth == 0 and char == ",":
            items.append(text[start:i])
            start = i + 1
    items.append(text[start:])
    return [item.strip() for item in items if item.strip()]


def parse_gym_name(name: str) -> tuple[str, dict[str, object]]:
    """``gym:ID[key=value,...]`` -> ``(ID, {key: value})`` (the form the domain's name takes).

    Raises:
        UnknownNameError: a malformed bracket (the message shows the expected form).
    """
    return parse_bracket_name(
        name, GYM_PREFIX, "gym:FrozenLake-v1[map_name=8x8,is_slippery=true]", "Gymnasium"
    )


def parse_minigrid_name(name: str) -> tuple[str, dict[str, object]]:
    """``minigrid:ID[seed=1,key=value,...]`` -> ``(ID, {key: value})``.

    Raises:
        UnknownNameError: a malformed bracket (the message shows the expected form).
    """
    return parse_bracket_name(name, MINIGRID_PREFIX, "minigrid:MiniGrid-DoorKey-5x5-v0[seed=1]",
                              "MiniGrid")


def parse_bracket_name(
    name: str, prefix: str, example: str, what: str
) -> tuple[str, dict[str, object]]:
    """``PREFIX ID[key=value,...]`` -> ``(ID, {key: value})``; ``example`` shows the form."""
    body = name.removeprefix(prefix)
    if "[" not in body:
        return body, {}
    env_id, _, rest = body.partition("[")
    if not rest.endswith("]") or not env_id:
        raise UnknownNameError(
            f"cannot read {name!r}: write {what} keyword arguments as "
            f"{prefix}ID[key=value,...], e.g. {example}"
        )
    kwargs: dict[str, object] = {}
    for item in _split_arguments(rest[:-1]):
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise UnknownNameError(
                f"cannot read {item!r} in {name!r}: each keyword argument is key=value, e.g. "
                f"{example}"
            )
        kwargs[key.strip()] = _gym_value(value, name, key.strip())
    return env_id, kwargs


def gym_module(name: str) -> str | None:
    """The Python module ``gym:MODULE:Id-v0`` would import, or None (no import: a built-in
    domain or an already registered Gymnasium id)."""
    if not name.startswith(GYM_PREFIX):
        return None
    env_id = name.removeprefix(GYM_PREFIX).partition("[")[0]
    module, colon, _ = env_id.partition(":")
    return module if colon else None


def get_domain(name: str) -> Domain:
    """The environment called ``name``: a built-in domain, ``gym:<id>`` for Gymnasium or
    ``minigrid:<id>`` for one seeded MiniGrid layout.

    ``gym:ID[key=value,...]`` passes the keyword arguments to ``gymnasium.make`` (values
    ``true``/``false``, numbers or text), e.g. ``gym:FrozenLake-v1[map_name=8x8,is_slippery=true]``;
    ``minigrid:ID[seed=1,...]`` passes them to :class:`~adpart.envs.minigrid_adapter.MiniGridDomain`
    (its own ``seed``, ``gamma``, ``actions``, ``max_states``; the rest to ``gymnasium.make``).
    """
    if name.startswith(MINIGRID_PREFIX):
        from adpart.envs.minigrid_adapter import MiniGridDomain

        env_id, kwargs = parse_minigrid_name(name)
        return MiniGridDomain(env_id, **kwargs)
    if name.startswith(GYM_PREFIX):
        from adpart.envs.gym_adapter import GymDomain

        env_id, kwargs = parse_gym_name(name)
        return GymDomain(env_id, **kwargs)
    if name not in BUILTIN_DOMAINS:
        hint = difflib.get_close_matches(name, list(BUILTIN_DOMAINS), n=1)
        raise UnknownNameError(
            f"unknown environment {name!r}; known: {', '.join(BUILTIN_DOMAINS)}"
            + (f". Did you mean {hint[0]!r}?" if hint else "")
            + ". Gymnasium environments are named gym:<id>, e.g. gym:Taxi-v4; MiniGrid layouts "
            "minigrid:<id>, e.g. minigrid:MiniGrid-FourRooms-v0"
        )
    return load_class(BUILTIN_DOMAINS[name])()
