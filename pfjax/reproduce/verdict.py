"""One verdict on one claim of a source: a row of a reproduction's verdict table."""

from __future__ import annotations

from typing import NamedTuple

from pfjax.report.document import Table
from pfjax.report.markdown import table

#: What a verdict says. ``holds`` / ``does not hold``: pfjax's number meets / misses the criterion.
#: ``reproduced`` / ``not reproduced``: pfjax's number matches / misses the source's number within the
#: tolerance the criterion states. ``no verdict``: the data cannot decide (stated why), or the source
#: states no outcome to compare with (a row that shows what a reading of the source changes).
VERDICTS = ("holds", "does not hold", "reproduced", "not reproduced", "no verdict")
#: Whether a row is evidence. ``independent``: nothing in pfjax was chosen from it.
#: ``used to choose the convention``: the source's statement fixed a modelling convention, so the row
#: agrees by construction. ``chosen by filters from the source``: the row checks a reading selected
#: with criteria taken from the same source statements, or checks such a reading on the quantity a
#: filter chose it by, on the same simulation (it passes by construction). ``used to calibrate a parameter``: the
#: source's number set one of pfjax's parameters (named in the criterion), so matching it is by
#: construction. ``assumed``: the criterion rests on a parameter the source does not give (named in
#: the criterion): a threshold that defines the criterion where the source gives none (the horizon a
#: quantity is read at, what "stuck" or "-> 0" means). A tolerance on matching a number the source
#: does give (how close counts as reproduced) is stated with its reason and leaves a row independent.
BASES = (
    "independent",
    "used to choose the convention",
    "chosen by filters from the source",
    "used to calibrate a parameter",
    "assumed",
)
#: :data:`BASES`' entry for a row on a reading chosen by the source's own statements.
FILTERED = BASES[2]
#: :data:`BASES`' entry for a row on the statement that fixed a modelling convention.
CONVENTION = BASES[1]
#: :data:`BASES`' entry for a row whose criterion rests on an assumed parameter (named in it).
ASSUMED = BASES[4]


class Verdict(NamedTuple):
    """One row: ``claim`` (the source's words), ``path`` (or ``"—"``), ``subject`` (controller or
    case), ``criterion`` (what is compared, with units, stated before any number), ``pfjax`` and
    ``source`` (numbers as text; ``"—"`` where the source gives none), ``verdict``
    (:data:`VERDICTS`), ``basis`` (:data:`BASES`) and ``also``: a second basis that applies to the
    same row (``""`` for none; ``basis`` is then the stronger of the two)."""

    claim: str
    path: str
    subject: str
    criterion: str
    pfjax: str
    source: str
    verdict: str
    basis: str = "independent"
    also: str = ""

    def check(self) -> Verdict:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict: {self.verdict!r} is not one of {VERDICTS}")
        if self.basis not in BASES:
            raise ValueError(f"basis: {self.basis!r} is not one of {BASES}")
        if self.also and (self.also not in BASES[1:] or self.also == self.basis):
            raise ValueError(f"also: {self.also!r} is not one of {BASES[1:]} other than the basis")
        return self


def verdict_cells(rows) -> tuple[list[str], list[list[str]]]:
    """The verdict table as ``(header, rows)`` of inline-Markdown cells; ``rows`` are
    :class:`Verdict` or their dicts (a summary's ``verdicts``). A row with two bases shows both in
    its basis cell, the stronger first."""
    head = ["claim", "path", "subject", "criterion", "pfjax", "source", "verdict", "basis"]
    cells = []
    for r in rows:
        v = r if isinstance(r, Verdict) else Verdict(**r)
        basis = "" if v.basis == "independent" else v.basis
        if v.also:
            basis += f"; also {v.also}"
        cells.append([v.claim, v.path, v.subject, v.criterion, v.pfjax, v.source, f"**{v.verdict}**", basis])
    return head, cells


def verdict_table(rows: list[Verdict]) -> str:
    """The verdict table in Markdown (cells escaped: evidence such as ``|d|`` stays in its cell)."""
    return table(*verdict_cells(rows))


def verdict_block(rows) -> Table:
    """The verdict table as a report block (:mod:`pfjax.report.document`)."""
    return Table(*verdict_cells(rows))
