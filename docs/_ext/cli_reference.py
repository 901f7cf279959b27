"""The ``volseg-cli`` directive: the command line's reference, generated from its own
parser (`volseg.cli._get_parser`), so the page cannot drift from ``--help``."""

from __future__ import annotations

import os

from docutils import nodes
from sphinx.util.docutils import SphinxDirective

#: Columns argparse wraps the help at (its default reads the terminal's).
WIDTH = "88"


def _subcommands(parser) -> dict:
    """name -> sub-parser, in the order ``--help`` lists them."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


class CliReference(SphinxDirective):
    """One section per command: its one-line purpose and its full ``--help``."""

    def run(self):
        from volseg.cli import _get_parser

        before = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = WIDTH
        try:
            parser = _get_parser()
            out = [nodes.literal_block(text=parser.format_help())]
            for name, sub in _subcommands(parser).items():
                section = nodes.section(ids=[f"volseg-{name}"])
                section += nodes.title(text=f"volseg {name}")
                section += nodes.literal_block(text=sub.format_help())
                out.append(section)
        finally:
            if before is None:
                os.environ.pop("COLUMNS", None)
            else:
                os.environ["COLUMNS"] = before
        return out


def setup(app):
    app.add_directive("volseg-cli", CliReference)
    return {"parallel_read_safe": True, "version": "1"}
