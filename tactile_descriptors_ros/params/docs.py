"""``docs/nodes.md``'s parameter tables, written from the node schemas.

Each table sits between two markers in the page::

    <!-- BEGIN parameters window_node (generated: python -m tactile_descriptors_ros.params.docs docs/nodes.md) -->
    | parameter | ...
    <!-- END parameters window_node -->

``python -m tactile_descriptors_ros.params.docs docs/nodes.md`` rewrites
every such block from :data:`~tactile_descriptors_ros.params.SCHEMAS`
(``--check`` only says whether they are current; a test runs it), and the
block ``tunable`` lists what each node lets change at run time.  Text
outside the markers is left as it is.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from .schema import NodeSchema, Param, describe_range, robot_default

__all__ = ["node_table", "tunable_table", "render", "main"]

_BLOCK = re.compile(r"(<!-- BEGIN parameters (?P<name>[\w-]+)[^>]*-->\n)(?P<body>.*?)(<!-- END parameters (?P=name) -->)",
                    re.S)
_QOS = re.compile(r"^qos\.(?P<endpoint>\w+)\.(?P<policy>reliability|durability|depth)$")


def _code(value: Any) -> str:
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, str):
        return f"`{value}`" if value else "`''`"
    if isinstance(value, (list, tuple)):
        return "`[" + ", ".join(map(str, value)) + "]`"
    return f"`{value:g}`" if isinstance(value, float) else f"`{value}`"


def _default(p: Param) -> str:
    if p.robot is not None:
        return f"robot's `{p.robot}` ({_code(robot_default(p.robot))} when unset)"
    if p.like is not None:
        return f"`{p.like}`"
    if p.derived is not None:
        return p.derived
    return _code(p.default)


def _accepted(p: Param) -> str:
    if p.range is not None:
        return describe_range(p) + (f" {p.unit}" if p.unit else "")
    if p.choices is not None:
        return ("each of " if p.type.endswith("_array") else "") + ", ".join(_code(c) for c in p.choices)
    return ""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def node_table(schema: NodeSchema) -> str:
    """The Markdown table of one node's parameters (a QoS endpoint's three parameters on one row)."""
    lines = ["| parameter | type | default | accepted | set at run time | description |",
             "| --- | --- | --- | --- | --- | --- |"]
    qos: dict[str, dict[str, Param]] = {}
    for p in schema:
        m = _QOS.match(p.name)
        if m:
            qos.setdefault(m["endpoint"], {})[m["policy"]] = p
    done: set[str] = set()
    for p in schema:
        m = _QOS.match(p.name)
        if m and len(qos[m["endpoint"]]) == 3:
            endpoint = m["endpoint"]
            if endpoint in done:
                continue
            done.add(endpoint)
            q = qos[endpoint]
            lines.append(f"| `qos.{endpoint}.*` | string, string, integer | "
                         f"{', '.join(_code(q[k].default) for k in ('reliability', 'durability', 'depth'))} | "
                         f"reliability, durability as in *QoS*; depth {describe_range(q['depth'])} | | "
                         f"QoS of '{endpoint}' (section *QoS*) |")
            continue
        lines.append(f"| `{p.name}` | {p.type.replace('_', ' ')} | {_cell(_default(p))} | {_cell(_accepted(p))} | "
                     f"{'yes' if p.tunable else ''} | {_cell(p.description)} |")
    return "\n".join(lines) + "\n"


def tunable_table(schemas: Mapping[str, NodeSchema]) -> str:
    """node | its parameters writable at run time."""
    lines = ["| node | writable at run time |", "| --- | --- |"]
    for exe, schema in schemas.items():
        names = [f"`{p.name}`" for p in schema.tunable()]
        lines.append(f"| {exe} | {', '.join(names) or 'none'} |")
    return "\n".join(lines) + "\n"


def render(text: str, schemas: Mapping[str, NodeSchema]) -> str:
    """``text`` with every parameter block rewritten from ``schemas``.

    Raises
    ------
    ConfigError
        For a block naming no known node, or a node without a block.
    """
    seen: set[str] = set()

    def body(m: re.Match) -> str:
        name = m["name"]
        seen.add(name)
        if name == "tunable":
            table = tunable_table(schemas)
        elif name in schemas:
            table = node_table(schemas[name])
        else:
            raise ConfigError(f"a parameter block names {name!r}, which has no schema "
                              f"(known: tunable, {', '.join(schemas)})", key=name)
        return m.group(1) + table + m.group(4)

    out = _BLOCK.sub(body, text)
    missing = [n for n in ("tunable", *schemas) if n not in seen]
    if missing:
        raise ConfigError(f"no parameter block for {', '.join(missing)} (add '<!-- BEGIN parameters NAME -->' and "
                          f"'<!-- END parameters NAME -->' lines)", key="docs")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Rewrite (or ``--check``) the parameter tables of a Markdown page; exit 1 when ``--check`` finds them stale."""
    from . import SCHEMAS

    ap = argparse.ArgumentParser(prog="python -m tactile_descriptors_ros.params.docs", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("page", type=Path, help="the Markdown page (docs/nodes.md)")
    ap.add_argument("--check", action="store_true", help="only check that the tables are current")
    args = ap.parse_args(argv)
    text = args.page.read_text()
    new = render(text, SCHEMAS)
    if args.check:
        if new != text:
            print(f"{args.page}: parameter tables differ from the node schemas; run "
                  f"python -m tactile_descriptors_ros.params.docs {args.page}", file=sys.stderr)
            return 1
        return 0
    if new != text:
        args.page.write_text(new)
        print(f"{args.page}: parameter tables rewritten")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
