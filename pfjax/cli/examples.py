"""``pfjax examples``: the example studies packaged with pfjax (:mod:`pfjax.examples`), each with
one line about it; run one with ``pfjax study --example NAME``."""

from __future__ import annotations


def _cmd(args) -> dict:
    from pfjax import examples

    return examples.describe()


def register(sub) -> None:
    helptext = "list the example studies packaged with pfjax (run one with pfjax study --example NAME)"
    p = sub.add_parser("examples", help=helptext, description=helptext)
    p.add_argument("--json", action="store_true", help="print one JSON object {name: description}")
    p.set_defaults(func=_cmd)
