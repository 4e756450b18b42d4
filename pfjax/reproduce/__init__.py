"""The source systems' claims, checked: verdict rows built from pfjax's own runs.

Each reproduced source has a module that turns the runs of its study into :class:`Verdict` rows:
one row per claim, path and criterion, with the criterion stated before the number, pfjax's
number, the source's where it gives one, the verdict, and the *basis* of the verdict (whether the
row is independent evidence, or was used to choose a convention or a reading and so cannot
confirm it).
"""

from pfjax.reproduce.verdict import BASES, VERDICTS, Verdict, verdict_table

__all__ = ["BASES", "VERDICTS", "Verdict", "verdict_table"]
