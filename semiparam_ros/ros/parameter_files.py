"""Which ``--params-file`` files apply to a node: ROS 2's node-name keys, read before the node trusts them.

A ROS 2 parameter file holds one block per node key. rcl applies a block to a node whose fully
qualified name the key matches: a key without a leading ``/`` is taken from the root (``estimator`` is
``/estimator``), ``*`` matches within one name token and ``**`` any number of tokens (``/**`` is every
node in every namespace). A file keyed ``estimator:`` therefore does not reach ``/arm/estimator``: the
node would start on its defaults — another robot — with nothing said. :func:`unmatched_files_message`
says so before it does.

And rcl reads ``--params-file`` after every ``-p``: a value in a ``/**`` block silently beats the same
parameter given with ``-p`` on the command line. :func:`command_line_assignments` gives the node the
``-p`` values back, so that the command line wins, as a user expects.

>>> key_matches("/**", "/arm/estimator"), key_matches("estimator", "/arm/estimator")
(True, False)
>>> key_matches("/arm/*", "/arm/estimator"), key_matches("/**/estimator", "/a/b/estimator")
(True, True)
>>> parameter_files(["--lifecycle", "--ros-args", "-r", "__ns:=/arm", "--params-file", "a.yaml", "--",
...                  "--ros-args", "--params-file=b.yaml"])
[PosixPath('a.yaml'), PosixPath('b.yaml')]
>>> command_line_assignments(["--ros-args", "--params-file", "a.yaml", "-p", "robot.joints:=[j1, j2]",
...                           "--param", "checkpoint.period:=5.0", "-p", "other_node:x:=1"])
{'robot.joints': ['j1', 'j2'], 'checkpoint.period': 5.0}
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import yaml

__all__ = ["command_line_assignments", "file_keys", "key_matches", "parameter_files",
           "unmatched_files_message"]

_ROS_ARGS = "--ros-args"
_END = "--"
_FLAG = "--params-file"


def _ros_options(argv: Sequence[str], flags: tuple[str, ...]) -> Iterator[tuple[str, str]]:
    """Yield ``(flag, value)`` for each of ``flags`` in the ``--ros-args`` sections, in order.

    Both forms count: ``flag value`` and ``flag=value``.
    """
    inside = False
    args = list(argv)
    for i, arg in enumerate(args):
        if arg == _ROS_ARGS:
            inside = True
        elif arg == _END:
            inside = False
        elif inside and arg in flags and i + 1 < len(args):
            yield arg, args[i + 1]
        elif inside and "=" in arg and arg.split("=", 1)[0] in flags:
            flag, value = arg.split("=", 1)
            yield flag, value


def parameter_files(argv: Sequence[str]) -> list[Path]:
    """Return the ``--params-file`` paths of the ``--ros-args`` sections of a command line, in order.

    Args:
        argv: The command line (program name or not).

    Returns:
        The paths (none when there is no ``--ros-args`` section).
    """
    return [Path(value) for _, value in _ros_options(argv, (_FLAG,))]


def command_line_assignments(argv: Sequence[str]) -> dict[str, Any]:
    """Return the ``-p name:=value`` assignments of the ``--ros-args`` sections for every node, in order.

    Values are read as YAML, as rcl reads them (``5.0`` a double, ``[a, b]`` a string array, ``abc`` a
    string). Assignments to a named node (``-p node:name:=value``) are left to rcl, whose node-specific
    values already beat ``/**`` blocks.

    Args:
        argv: The command line.

    Returns:
        Parameter names to values; a later assignment of a name replaces an earlier one.
    """
    out: dict[str, Any] = {}
    for _, rule in _ros_options(argv, ("-p", "--param")):
        name, sep, text = rule.partition(":=")
        if not sep or ":" in name:
            continue
        try:
            out[name] = yaml.safe_load(text) if text else ""
        except yaml.YAMLError:
            out[name] = text  # rcl refuses it with its own message
    return out


def key_matches(key: str, fully_qualified_name: str) -> bool:
    """Whether a parameter file's node key applies to a node (rcl's rule: ``*``, ``**``, root-relative).

    Args:
        key: A top-level key of a parameter file (``/**``, ``estimator``, ``/arm/*``…).
        fully_qualified_name: The node's name with its namespace (``/arm/estimator``).

    Returns:
        Whether the block under ``key`` is applied to the node.
    """
    key = key if key.startswith("/") else "/" + key
    pattern = ""
    for token in key.strip("/").split("/"):
        if token == "**":
            pattern += "(/[^/]+)*"
        else:
            pattern += "/" + "[^/]*".join(re.escape(part) for part in token.split("*"))
    return re.fullmatch(pattern or "/", fully_qualified_name) is not None


def file_keys(path: Path) -> list[str]:
    """Return the top-level keys of a parameter file (empty when it cannot be read as a mapping)."""
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError):
        return []  # rcl itself refuses an unreadable file, with its own message
    return [str(k) for k in document] if isinstance(document, dict) else []


def unmatched_files_message(files: Sequence[Path], fully_qualified_name: str) -> str | None:
    """Say why no given parameter file applies to the node, or None when one does (or none is given).

    Args:
        files: The ``--params-file`` paths.
        fully_qualified_name: The node's fully qualified name.

    Returns:
        A message naming each file's keys and the node's name, with the fix; None if any key matches.

    >>> import tempfile, pathlib
    >>> f = pathlib.Path(tempfile.mkdtemp()) / "kuka.yaml"
    >>> _ = f.write_text(chr(10).join(["estimator:", "  ros__parameters: {}", ""]))
    >>> unmatched_files_message([f], "/estimator") is None
    True
    >>> message = unmatched_files_message([f], "/arm/estimator")
    >>> "applies to this node, /arm/estimator" in message, "has 'estimator'" in message
    (True, True)
    """
    if not files:
        return None
    found = {path: file_keys(path) for path in files}
    if any(key_matches(k, fully_qualified_name) for keys in found.values() for k in keys):
        return None
    listing = "; ".join(f"{path} has {', '.join(repr(k) for k in keys) or 'no node keys'}"
                        for path, keys in found.items())
    return (f"no parameter file applies to this node, {fully_qualified_name}: {listing}. Key the block "
            f"'/**:' (any node, any namespace) or '{fully_qualified_name}:'")
